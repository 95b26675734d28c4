"""psyop: gaze-contingent VR psychophysics.

The data path runs one way (see DESIGN notes in the README):

    protocol -> schedule -> session (clock, gaze, responses, log) -> analysis
                             rendering <- optics
    statistics (tables in, tables out)
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("psyop")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]

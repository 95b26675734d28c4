"""psyop: gaze-contingent VR psychophysics.

The data path runs one way (docs/architecture.md; the layers are checked by import-linter, .importlinter):

    protocol -> schedule -> stimulus -> session (plan, clock, loop, log) -> run -> data/ (parquet)
    optics -> rendering ----^            ^ seams        devices (adapters)--^
    data/ -> quality -> statistics | audit | export -> figures | power -> cli, analysis/
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("psyop")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]

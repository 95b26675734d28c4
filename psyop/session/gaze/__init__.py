"""Gaze sources: a common sample type and interchangeable backends.

Sources here: :mod:`.simulated` (synthetic eye movements), :mod:`.replay` (a logged
session's frames); the device adapters (Pupil Core, LSL, serial lines) are in
:mod:`psyop.devices.gaze`. :mod:`.filter` holds the last valid gaze and applies
the per-trial single-point drift recalibration.
"""

from psyop.session.gaze.sample import GazeSample, GazeSource, TrackerLost

__all__ = ["GazeSample", "GazeSource", "TrackerLost"]

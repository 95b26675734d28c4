"""Gaze sources: a common sample type and interchangeable backends.

Backends: :mod:`.simulated` (synthetic eye movements), :mod:`.replay` (a logged
session's frames), :mod:`.pupil` (Pupil Core Network API over ZMQ), :mod:`.serial_source`
(line protocol over a serial port). :mod:`.filter` holds the last valid gaze and applies
the per-trial single-point drift recalibration.
"""

from psyop.session.gaze.sample import GazeSample, GazeSource, TrackerLost

__all__ = ["GazeSample", "GazeSource", "TrackerLost"]

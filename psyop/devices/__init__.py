"""Hardware adapters: each implements one of the session's seams (a GazeSource, a Display, a
ResponseSource, a PoseSource, an EventSink) over a device or a network stream.

OpenXR headsets (xr), Pupil Core (gaze.pupil), LSL gaze streams (gaze.lsl, gaze.lsl_channels), serial
gaze lines (gaze.serial_source), the desktop window (window), its keyboard (responses.keyboard), the
serial response box (responses.serial_box), LSL marker outlets (lsl_markers) and the serial line reader
they share (serial_lines). They import the session's contracts (psyop.session), never the reverse:
the session's backend registry (psyop.run.backends) and assembly (psyop.run.assembly) import
them by name, only when a session asks for one. docs/architecture.md.
"""

"""Gaze adapters over devices: Pupil Core (pupil), LSL streams (lsl, lsl_channels), serial lines (serial_source).
The sample type, the simulated and replayed sources stay in psyop.session.gaze."""

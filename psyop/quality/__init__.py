"""Gaze data quality, eye-movement events (pymovements) and the protocol's exclusion rules.

Reads what sessions recorded (the raw gaze stream, the trial log, the protocol in session.json) and
never changes it: ``samples`` puts a session's samples on the tracker's clock grid, ``target`` rebuilds
the target the participant was asked to look at, ``events`` detects fixations and saccades with pymovements,
``measures`` computes the per-trial and per-session measures, ``rules`` applies a ``quality:``
section. docs/quality.md says what each number is.
"""

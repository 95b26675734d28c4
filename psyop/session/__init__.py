"""Sessions: clock, gaze sources, responses (incl. simulated observers), durable log, trial loop.

See docs/sessions.md for the design and the data layout.
"""

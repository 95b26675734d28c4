"""Exports of a data root into data standards, each checked by that standard's own validator.

- :mod:`psyop.export.bids`: ``psyop export --bids DIR`` (BIDS, with BEP020 eye tracking; checked by
  ``bids-validator-deno`` in tests/export).
- :mod:`psyop.export.gaze`: the session's gaze samples (raw stream preferred, else the frame log)
  and where each eye's line of sight meets its display image.

No other standard is claimed: Psych-DS's validator is not installable here, so psyop writes no
Psych-DS dataset and its native data/ layout claims none (docs/data.md).
"""

"""Protocol texts shared by tests that need a small two-interval study around their own scene."""

from __future__ import annotations

#: phases, design and response of a minimal 2IFC study: ocular test vs conventional reference,
#: level_D 0 and 1, one repetition (append it to a header and a ``scene:`` list)
TWO_INTERVAL_TAIL = """trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    level_D: {levels: [0, 1]}
  repetitions: 1
  randomisation: {kind: full}
response:
  kind: two_interval
  test: {mode: ocular}
  reference: {mode: conventional}
  level_factor: level_D
  order: balanced
"""

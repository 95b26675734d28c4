"""Trial schedules: protocol + seed -> one row per trial (docs/architecture.md, "the trial table").

Public API: :func:`compile_schedule`, :func:`expected_duration_s`, :func:`trial_count`,
:func:`write_schedule`, :func:`read_schedule`, :func:`interval_values`.
"""

from __future__ import annotations

import importlib
from typing import Any

# Imported on first use (PEP 562), so that `psyop validate` does not pay for pandas.
_HOME = {"check_seed": "compile", "compile_schedule": "compile", "expected_duration_s": "counts",
         "trial_count": "counts", "read_schedule": "io", "schedule_table": "io", "write_schedule": "io",
         "interval_values": "rows"}

__all__ = ["check_seed", "compile_schedule", "expected_duration_s", "interval_values", "read_schedule", "schedule_table",
           "trial_count", "write_schedule"]


def __getattr__(name: str) -> Any:  # Any: whichever attribute of the lazily imported module is asked for
    if name in _HOME:
        return getattr(importlib.import_module(f"psyop.schedule.{_HOME[name]}"), name)
    raise AttributeError(f"module 'psyop.schedule' has no attribute {name!r}")

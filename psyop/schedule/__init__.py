"""Trial schedules: protocol + seed -> one row per trial (docs/architecture.md, "the trial table").

Public API: :func:`compile_schedule`, :func:`expected_duration_s`, :func:`trial_count`,
:func:`write_schedule`, :func:`read_schedule`, :func:`interval_values`.
"""

from psyop.schedule.compile import check_seed, compile_schedule, expected_duration_s, trial_count
from psyop.schedule.io import read_schedule, schedule_table, write_schedule
from psyop.schedule.rows import interval_values

__all__ = ["check_seed", "compile_schedule", "expected_duration_s", "interval_values", "read_schedule", "schedule_table",
           "trial_count", "write_schedule"]

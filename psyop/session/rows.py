"""Named types for the session's heterogeneous mappings, so each carries its reason once.

A schedule row or trial record maps column names to values whose columns depend on the protocol (its
factors, its response kind) and whose values are numpy/pandas scalars, strings or None; session.json and
the summaries a source reports are JSON objects. None of them can be typed further without a model per
protocol, so ``Any`` stands here, once, with that reason.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["JsonMapping", "JsonObject", "TrialRecord", "TrialRow"]

#: one schedule row (read only): column -> value (protocol-dependent columns, numpy/pandas scalars)
TrialRow = Mapping[str, Any]  # Any: protocol-dependent columns (module docstring)
#: one trial's record as the loop fills it (the schedule row plus response, timing and gaze columns)
TrialRecord = dict[str, Any]  # Any: as TrialRow
#: a JSON object: session.json, a source's stats/summary, an event's fields
JsonObject = dict[str, Any]  # Any: JSON values
#: a JSON-like mapping read, not written: observer parameters, a summary handed to the log, a stream's identity
JsonMapping = Mapping[str, Any]  # Any: JSON values

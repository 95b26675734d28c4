"""Named types for the session's heterogeneous mappings, so each carries its reason once.

A schedule row or trial record maps column names to values whose columns depend on the protocol (its
factors, its response kind) and whose values are numpy/pandas scalars, strings or None; session.json and
the summaries a source reports are JSON objects. None of them can be typed further without a model per
protocol, so ``Any`` stands here, once, with that reason.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the command line's --help imports this module: no pandas or numpy at import
    import pandas as pd

__all__ = ["JsonMapping", "JsonObject", "TrialRecord", "TrialRow", "frame_records"]

#: one schedule row (read only): column -> value (protocol-dependent columns, numpy/pandas scalars)
TrialRow = Mapping[str, Any]  # Any: protocol-dependent columns (module docstring)
#: one trial's record as the loop fills it (the schedule row plus response, timing and gaze columns)
TrialRecord = dict[str, Any]  # Any: as TrialRow
#: a JSON object: session.json, a source's stats/summary, an event's fields
JsonObject = dict[str, Any]  # Any: JSON values
#: a JSON-like mapping read, not written: observer parameters, a summary handed to the log, a stream's identity
JsonMapping = Mapping[str, Any]  # Any: JSON values


def frame_records(frame: pd.DataFrame) -> list[TrialRecord]:
    """``frame.to_dict("records")``: one dict per row, Python scalars, in column order. A frame of numpy
    bool, integer and float columns and pandas' default string columns (missing: NaN; a compiled schedule) is read column by
    column (``Series.tolist``: the same values and types, about 4x faster than pandas' per-cell boxing, which
    was 3 % of a simulated replication); any other frame (object, nullable or datetime columns, repeated
    names, strings whose missing value is pd.NA, which pandas turns into None) goes through pandas itself.

    Examples
    --------
    >>> import pandas as pd
    >>> frame = pd.DataFrame({"trial": [0, 1], "level_D": [0.25, 0.5], "mode": pd.array(["a", "b"], dtype="str")})
    >>> frame_records(frame) == frame.to_dict("records")
    True
    """
    import numpy as np
    import pandas as pd

    plain = len(frame.columns) > 0 and frame.columns.is_unique and all(
        (isinstance(dtype, np.dtype) and dtype.kind in "biuf")
        or (isinstance(dtype, pd.StringDtype) and isinstance(dtype.na_value, float))  # NaN-missing strings
        for dtype in frame.dtypes)
    if not plain:
        return frame.to_dict("records")
    names = list(frame.columns)
    return [dict(zip(names, values)) for values in zip(*(frame[name].tolist() for name in names))]

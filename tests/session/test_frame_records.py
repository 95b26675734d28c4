"""frame_records (psyop.session.rows) equals DataFrame.to_dict("records") value for value and type for type:
on the schedules of every shipped protocol (and the examples), and on frames with the columns it hands to
pandas (object, nullable, datetime, pd.NA strings, repeated names, none)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule
from psyop.session.rows import frame_records

ROOT = Path(__file__).resolve().parents[2]
PROTOCOLS = sorted((ROOT / "protocols").rglob("*.yaml"))


def _same(got: list[dict], want: list[dict]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want):
        assert list(a) == list(b)
        for key in a:
            x, y = a[key], b[key]
            assert type(x) is type(y), (key, x, y)
            assert x == y or x is y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)), (key, x, y)


@pytest.mark.parametrize("path", PROTOCOLS, ids=lambda p: p.stem)
def test_schedules_of_every_shipped_protocol(path: Path):
    protocol = parse_protocol(path.read_text(), str(path))
    for seed, participant in ((0, 0), (7, 3)):
        schedule = compile_schedule(protocol, seed, participant)
        _same(frame_records(schedule), schedule.to_dict("records"))


def test_numpy_and_string_columns_with_missing_values():
    frame = pd.DataFrame({"i": np.array([1, 2, 3], dtype=np.int32), "u": np.array([1, 2, 3], dtype=np.uint8),
                          "f": [0.5, np.nan, -0.0], "b": [True, False, True],
                          "s": pd.array(["x", None, "z"], dtype="str")})
    _same(frame_records(frame), frame.to_dict("records"))


@pytest.mark.parametrize("frame", [
    pd.DataFrame({"o": [None, "y"], "n": [np.int64(3), 4.5]}, dtype=object),
    pd.DataFrame({"d": pd.array([1, None], dtype="Int64")}),
    pd.DataFrame({"t": pd.to_datetime(["2020-01-01", None])}),
    pd.DataFrame({"s": pd.array(["x", None], dtype="string")}),
    pd.DataFrame([[1, 2]], columns=["a", "a"]),
    pd.DataFrame(index=range(2)),
], ids=["object", "nullable-int", "datetime", "na-strings", "repeated-names", "no-columns"])
def test_other_frames_go_through_pandas(frame: pd.DataFrame):
    want = frame.to_dict("records") if frame.columns.is_unique else None
    if want is None:
        with pytest.warns(UserWarning):
            want = frame.to_dict("records")
        with pytest.warns(UserWarning):
            got = frame_records(frame)
    else:
        got = frame_records(frame)
    _same(got, want)

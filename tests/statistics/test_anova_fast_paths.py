"""psyop.statistics.anova's fast paths, held to the definitions they replaced (kept here as ``_old_*``):
the error sums of squares read off a complete design without ``pivot_table`` (same values in the
pivot's memory layout, so the same reductions), the incomplete-subject search answering at once for a
complete design, and ``rm_anova`` passing pingouin only the subject, factor and value columns. On many
random one- and two-way designs (string, integer and float keys, shuffled rows, extra columns, missing
cells, NaN values and levels, categorical factors, ties and constant cells) every result must be the same
bit for bit, and the same errors must be raised."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pandas as pd
import pingouin as pg
import pytest

from psyop.statistics import anova as an
from psyop.statistics.anova import (ANOVA_COLUMNS, AnovaResult, ZERO_SS_REL, AnovaInputError, _check_enough_subjects,
                                    _quiet_pingouin, _row, check_level_names, error_sums_of_squares,
                                    find_incomplete_subjects, rm_anova)

pytestmark = pytest.mark.cross_cpu  # fast paths against the former code beside them, bit for bit


# ---- the former implementations ----------------------------------------------------------------------------------

def _old_find_incomplete_subjects(data, dv, within, subject):
    within = list(within)
    levels = [sorted(data[w].dropna().unique(), key=str) for w in within]
    complete = data[np.isfinite(pd.to_numeric(data[dv], errors="coerce"))]
    present = {tuple(r) for r in complete[[subject, *within]].itertuples(index=False)}
    rows = []
    for s in sorted(data[subject].unique(), key=str):
        missing = [c for c in itertools.product(*levels) if (s, *c) not in present]
        if missing:
            cells = "; ".join(", ".join(f"{w}={v}" for w, v in zip(within, c)) for c in missing)
            rows.append({"subject": s, "reason": f"missing cell(s): {cells}"})
    return pd.DataFrame(rows, columns=["subject", "reason"])


def _old_error_sums_of_squares(data, dv, within, subject):
    within = list(within)
    wide = data.pivot_table(index=subject, columns=within, values=dv, aggfunc="first", observed=True)
    y = wide.to_numpy(float)
    total = float(((y - y.mean()) ** 2).sum())
    if len(within) == 1:
        r = y - y.mean(axis=1, keepdims=True) - y.mean(axis=0, keepdims=True) + y.mean()
        return {within[0]: float((r ** 2).sum()), "total": total}
    a = len(wide.columns.levels[0]) if hasattr(wide.columns, "levels") else 1
    y = y.reshape(len(wide), a, -1)
    b = y.shape[2]
    m_sa, m_sb, m_s = y.mean(axis=2), y.mean(axis=1), y.mean(axis=(1, 2))
    m_a, m_b, g = y.mean(axis=(0, 2)), y.mean(axis=(0, 1)), y.mean()
    r_a = m_sa - m_s[:, None] - m_a[None, :] + g
    r_b = m_sb - m_s[:, None] - m_b[None, :] + g
    m_ab = y.mean(axis=0)
    r_ab = (y - m_sa[:, :, None] - m_sb[:, None, :] + m_s[:, None, None]
            - (m_ab - m_a[:, None] - m_b[None, :] + g)[None])
    return {within[0]: float(b * (r_a ** 2).sum()), within[1]: float(a * (r_b ** 2).sum()),
            f"{within[0]} * {within[1]}": float((r_ab ** 2).sum()), "total": total}


def _old_rm_anova(data, dv, within, subject="participant"):
    within = [within] if isinstance(within, str) else list(within)
    if not 1 <= len(within) <= 2:
        raise ValueError("rm_anova supports one or two within-subject factors")
    if data.duplicated([subject, *within]).any():
        raise ValueError("more than one value per subject and cell; aggregate first (cell_means)")
    check_level_names(data, within, subject)
    dropped = _old_find_incomplete_subjects(data, dv, within, subject)
    kept = data[~data[subject].isin(dropped["subject"])].copy()
    kept[dv] = kept[dv].astype(float)
    max_levels = max(kept[w].nunique() for w in within) if len(kept) else 0
    n = _check_enough_subjects(kept, subject, max(2, max_levels), f"an rm-ANOVA with {max_levels} levels", dropped)
    error_ss = _old_error_sums_of_squares(kept, dv, within, subject)
    if error_ss["total"] <= 0.0 or np.ptp(kept[dv].to_numpy(float)) == 0.0:
        raise AnovaInputError(f"{dv!r} is the same value ({kept[dv].iloc[0]:g}) in every subject and cell: "
                              "there is no variance to test")
    with _quiet_pingouin(), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        aov = pg.rm_anova(kept, dv=dv, within=within if len(within) > 1 else within[0],
                          subject=subject, correction=True, detailed=True)
    rows = []
    zero = {k: v <= ZERO_SS_REL * error_ss["total"] for k, v in error_ss.items() if k != "total"}
    if len(within) == 1:
        effect, error = aov.iloc[0], aov.iloc[1]
        rows.append(_row(within[0], effect, int(effect["DF"]), int(error["DF"]), n, zero[within[0]]))
    else:
        for _, effect in aov.iterrows():
            rows.append(_row(effect["Source"], effect, int(effect["ddof1"]), int(effect["ddof2"]), n,
                             zero[effect["Source"]]))
    table = pd.DataFrame(rows, columns=ANOVA_COLUMNS)
    return AnovaResult(table=table, dropped=dropped, within=tuple(within), dv=dv, n_subjects=n)


# ---- random designs ----------------------------------------------------------------------------------------------

def _design(rng: np.random.Generator, case: int) -> tuple[pd.DataFrame, list[str]]:
    n_subj = int(rng.integers(2, 13))
    n_a = int(rng.integers(2, 6))
    n_b = int(rng.integers(2, 4))
    two_way = case % 2 == 1
    kind = case % 3
    subjects = ([f"S{i:02d}" for i in range(n_subj)] if kind == 0 else list(range(100, 100 + n_subj)) if kind == 1
                else [f"p{i}" for i in rng.permutation(n_subj)])
    a_levels = list(rng.choice([0.5, 1.0, 2.0, 3.0, 4.0, 6.0], n_a, replace=False)) if case % 4 < 2 else \
        [f"m{i}" for i in range(n_a)]
    b_levels = [f"s{i}" for i in range(n_b)] if two_way else [None]
    rows = []
    offsets = rng.normal(size=n_subj)
    for s, off in zip(subjects, offsets):
        for ia, a_ in enumerate(a_levels):
            for ib, b_ in enumerate(b_levels):
                value = off + 0.1 * ia + 0.05 * ib + rng.normal() * rng.choice([1.0, 1e-3, 0.0])
                row = {"participant": s, "a": a_, "v": value, "status": "ok", "flags": "x" * int(rng.integers(3))}
                if two_way:
                    row["b"] = b_
                rows.append(row)
    frame = pd.DataFrame(rows).iloc[rng.permutation(len(rows))]
    if case % 5 == 0:
        frame = frame.reset_index(drop=True)
    within = ["a", "b"] if two_way else ["a"]
    edit = case % 9
    if edit == 1:
        frame = frame.drop(frame.index[int(rng.integers(len(frame)))])  # a missing cell
    elif edit == 2:
        frame.loc[frame.index[int(rng.integers(len(frame)))], "v"] = np.nan  # a NaN value
    elif edit == 3:
        frame["v"] = np.round(frame["v"], 1)  # ties
    elif edit == 4:
        frame["a"] = frame["a"].astype("category")
    elif edit == 5 and len(frame) > 3:
        frame.loc[frame.index[0], "a"] = np.nan if case % 4 < 2 else None  # a NaN level
    elif edit == 6:
        frame["v"] = frame["v"].astype("float32")
    return frame, within


def _table_repr(result: AnovaResult) -> tuple:
    return (repr(result.table.to_numpy().tolist()), list(result.table.columns), repr(result.dropped.to_numpy().tolist()),
            list(result.dropped.columns), result.within, result.dv, result.n_subjects)


def _outcome(fn, *args):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return "ok", fn(*args)
    except (ValueError, KeyError, AnovaInputError) as exc:
        return type(exc).__name__, str(exc)


#: every combination of the designs' variations (case mod 2, 3, 4 and 9: 36 cases) twice; make bench runs all 240
@pytest.mark.parametrize("cases", [72, pytest.param(240, marks=pytest.mark.bench)])
def test_rm_anova_and_its_parts_equal_the_former_definitions(cases: int):
    rng = np.random.default_rng(30)
    for case in range(cases):
        frame, within = _design(rng, case)
        old, new = _outcome(_old_rm_anova, frame, "v", within), _outcome(rm_anova, frame, "v", within)
        assert old[0] == new[0], (case, old, new)
        if old[0] == "ok":
            assert _table_repr(new[1]) == _table_repr(old[1]), case
        else:
            assert old[1] == new[1]
        old_d = _old_find_incomplete_subjects(frame, "v", within, "participant")
        new_d = find_incomplete_subjects(frame, "v", within, "participant")
        assert repr(new_d.to_numpy().tolist()) == repr(old_d.to_numpy().tolist())
        assert list(new_d.columns) == list(old_d.columns) and list(new_d.dtypes) == list(old_d.dtypes)
        if old_d.empty and not frame.duplicated(["participant", *within]).any():
            kept = frame.copy()
            kept["v"] = kept["v"].astype(float)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                old_ss = _old_error_sums_of_squares(kept, "v", within, "participant")
                new_ss = error_sums_of_squares(kept, "v", within, "participant")
            assert repr(new_ss) == repr(old_ss), case


def test_complete_grid_values_are_the_pivot_in_its_layout():
    rng = np.random.default_rng(7)
    n_fast = 0
    for case in range(120):
        frame, within = _design(rng, case)
        grid = an._complete_grid_values(frame, "v", within, "participant")
        if grid is None:
            continue
        n_fast += 1
        wide = frame.pivot_table(index="participant", columns=within, values="v", aggfunc="first", observed=True)
        y = wide.to_numpy(float)
        assert grid[0].tobytes("A") == y.tobytes("A") and grid[0].strides == y.strides and grid[0].shape == y.shape
        if len(within) == 2:  # the first factor's level count (the one-way sums do not read it)
            assert grid[1] == len(wide.columns.levels[0])
    assert n_fast > 30


def test_incomplete_design_takes_the_former_path():
    frame = pd.DataFrame({"participant": ["a", "a", "b"], "c": [1, 2, 1], "v": [0.1, 0.2, 0.3]})
    assert an._complete_grid_values(frame, "v", ["c"], "participant") is None
    assert list(find_incomplete_subjects(frame, "v", ["c"], "participant")["subject"]) == ["b"]


def test_duplicate_cells_still_raise():
    frame = pd.DataFrame({"participant": ["a", "a", "b", "b"], "c": [1, 1, 1, 2], "v": [0.1, 0.2, 0.3, 0.4]})
    with pytest.raises(ValueError, match="more than one value"):
        rm_anova(frame, "v", "c")

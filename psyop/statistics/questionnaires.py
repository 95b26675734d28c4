"""Questionnaire answers (a session's questionnaires.parquet, psyop.session.screens) and their scores.

:func:`load_questionnaires` reads every session's answers of a study, each session's finalised files verified
first (psyop.finalised); :func:`ssq_scores` scores each Simulator Sickness Questionnaire administration by
Kennedy, Lane, Berbaum & Lilienthal (1993): the raw sums of the nausea (N), oculomotor (O) and
disorientation (D) items, N x 9.54, O x 7.58, D x 13.92 and total = (N + O + D raw sums) x 3.74 (the items,
their assignment and the weights: psyop.protocol.ssq).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from psyop.datacontract import QUESTIONNAIRES_FILE
from psyop.finalised import verify_session
from psyop.protocol import ssq

#: the columns that tell one administration from another in questionnaires.parquet
ADMINISTRATION_KEYS: tuple[str, ...] = ("study", "participant", "session", "run", "administration", "when",
                                        "before_trial")


def ssq_score(ratings: Sequence[float]) -> dict[str, float]:
    """The SSQ scores of one administration's 16 ratings (item 1 first, each 0-3): each subscale's raw sum
    (``nausea_raw``, ...), its weighted score (``nausea``, ``oculomotor``, ``disorientation``) and ``total``.
    A missing rating (None or NaN) makes every score NaN: the published scores need all 16.

    Examples
    --------
    >>> s = ssq_score([3] * 16)  # every symptom severe: the published maxima
    >>> round(s["nausea"], 2), round(s["oculomotor"], 2), round(s["disorientation"], 2), round(s["total"], 2)
    (200.34, 159.18, 292.32, 235.62)
    """
    values = np.array([math.nan if r is None else float(r) for r in ratings], dtype=np.float64)
    if values.shape != (len(ssq.ITEMS),):
        raise ValueError(f"the SSQ has {len(ssq.ITEMS)} items, got {values.size} ratings")
    finite = values[np.isfinite(values)]
    if finite.size and (np.any(finite < 0) or np.any(finite > len(ssq.SCALE_LABELS) - 1)
                        or np.any(finite != np.round(finite))):
        raise ValueError("SSQ ratings are whole numbers 0 to 3")
    out: dict[str, float] = {}
    for subscale in ssq.SUBSCALES:
        raw = float(values[list(ssq.subscale_items(subscale))].sum())
        out[f"{subscale}_raw"] = raw
        out[subscale] = raw * ssq.WEIGHTS[subscale]
    out["total"] = sum(out[f"{s}_raw"] for s in ssq.SUBSCALES) * ssq.TOTAL_WEIGHT
    return out


def ssq_scores(answers: pd.DataFrame) -> pd.DataFrame:
    """One row per SSQ administration in ``answers`` (questionnaires.parquet rows, any number of sessions):
    the :data:`ADMINISTRATION_KEYS` present, ``n_answered`` and the scores of :func:`ssq_score` (NaN where an
    item is unanswered or missing)."""
    rows = answers[answers["questionnaire"] == ssq.NAME]
    keys = [k for k in ADMINISTRATION_KEYS if k in rows.columns]
    out = []
    for key, group in rows.groupby(keys, sort=True, dropna=False):
        by_item = group.drop_duplicates("item", keep="last").set_index("item")["answer"]
        ratings = [by_item.get(i, math.nan) for i in range(len(ssq.ITEMS))]
        ratings = [math.nan if r is None or pd.isna(r) else float(r) for r in ratings]
        values = dict(zip(keys, key if isinstance(key, tuple) else (key,)))
        out.append({**values, "n_answered": int(np.isfinite(ratings).sum()), **ssq_score(ratings)})
    columns = [*keys, "n_answered", *(f"{s}_raw" for s in ssq.SUBSCALES), *ssq.SUBSCALES, "total"]
    return pd.DataFrame(out, columns=columns)


def load_questionnaires(data_root: Path, study: str) -> pd.DataFrame:
    """Every questionnaire answer of ``study``'s sessions under ``data_root`` (sessions without questionnaires
    add nothing), each session's finalised files verified first (a damaged or edited one: UserError)."""
    frames = []
    for path in sorted((Path(data_root) / study).glob(f"sub-*/ses-*/{QUESTIONNAIRES_FILE}")):
        verify_session(path.parent)
        frames.append(pd.read_parquet(path))
    if not frames:
        return pd.DataFrame(columns=["study", "participant", "session", "questionnaire", "item", "answer"])
    return pd.concat(frames, ignore_index=True)

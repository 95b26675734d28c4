"""SSQ scoring (psyop.statistics.questionnaires) against the published definition (Kennedy, Lane, Berbaum &
Lilienthal 1993: items, subscale assignment, weights; psyop.protocol.ssq) and a hand-computed example."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from psyop.protocol import ssq
from psyop.statistics.questionnaires import ssq_score, ssq_scores


def test_the_definition_is_the_published_one() -> None:
    assert len(ssq.ITEMS) == 16 and ssq.SCALE_LABELS == ("none", "slight", "moderate", "severe")
    # Kennedy et al. 1993, Table 4 (1-based item numbers)
    assert [i + 1 for i in ssq.subscale_items("nausea")] == [1, 6, 7, 8, 9, 15, 16]
    assert [i + 1 for i in ssq.subscale_items("oculomotor")] == [1, 2, 3, 4, 5, 9, 11]
    assert [i + 1 for i in ssq.subscale_items("disorientation")] == [5, 8, 10, 11, 12, 13, 14]
    assert ssq.WEIGHTS == {"nausea": 9.54, "oculomotor": 7.58, "disorientation": 13.92}
    assert ssq.TOTAL_WEIGHT == 3.74
    assert ssq.item_texts()[0] == "General discomfort" and ssq.item_texts()[-1] == "Burping"


def test_a_hand_computed_example() -> None:
    ratings = [1, 0, 2, 1, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1, 0, 0]
    # N: items 1, 6, 7, 8, 9, 15, 16 -> 1 + 0 + 1 + 0 + 1 + 0 + 0 = 3
    # O: items 1, 2, 3, 4, 5, 9, 11 -> 1 + 0 + 2 + 1 + 0 + 1 + 2 = 7
    # D: items 5, 8, 10, 11, 12, 13, 14 -> 0 + 0 + 0 + 2 + 0 + 0 + 1 = 3
    s = ssq_score(ratings)
    assert (s["nausea_raw"], s["oculomotor_raw"], s["disorientation_raw"]) == (3, 7, 3)
    assert s["nausea"] == pytest.approx(28.62)
    assert s["oculomotor"] == pytest.approx(53.06)
    assert s["disorientation"] == pytest.approx(41.76)
    assert s["total"] == pytest.approx(48.62)  # (3 + 7 + 3) x 3.74


def test_published_maxima_and_zero() -> None:
    top = ssq_score([3] * 16)
    assert top["nausea"] == pytest.approx(200.34) and top["oculomotor"] == pytest.approx(159.18)
    assert top["disorientation"] == pytest.approx(292.32) and top["total"] == pytest.approx(235.62)
    assert all(v == 0 for v in ssq_score([0] * 16).values())


def test_bad_ratings_are_refused_and_missing_ones_give_nan() -> None:
    with pytest.raises(ValueError, match="16 items"):
        ssq_score([0] * 15)
    with pytest.raises(ValueError, match="0 to 3"):
        ssq_score([4] + [0] * 15)
    assert math.isnan(ssq_score([None] + [1] * 15)["total"])


def test_scores_per_participant_and_administration() -> None:
    example = [1, 0, 2, 1, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1, 0, 0]
    rows = []
    for participant, when, ratings in (("S01", "start", [0] * 16), ("S01", "end", example),
                                       ("S02", "end", [3] * 16)):
        rows += [{"study": "s", "participant": participant, "session": 1, "run": 0,
                  "administration": 1 if when == "start" else 2, "when": when, "before_trial": 0 if when == "start" else -1,
                  "questionnaire": "ssq", "item": i, "answer": a} for i, a in enumerate(ratings)]
    rows.append({"study": "s", "participant": "S01", "session": 1, "run": 0, "administration": 3, "when": "end",
                 "before_trial": -1, "questionnaire": "comfort", "item": 0, "answer": 2})  # not an SSQ
    rows += [{"study": "s", "participant": "S03", "session": 1, "run": 0, "administration": 1, "when": "end",
              "before_trial": -1, "questionnaire": "ssq", "item": i, "answer": None} for i in range(16)]
    scores = ssq_scores(pd.DataFrame(rows)).set_index(["participant", "when"])
    assert len(scores) == 4
    assert scores.loc[("S01", "start"), "total"] == 0
    assert scores.loc[("S01", "end"), "total"] == pytest.approx(48.62)
    assert scores.loc[("S02", "end"), "disorientation"] == pytest.approx(292.32)
    assert scores.loc[("S03", "end"), "n_answered"] == 0 and math.isnan(scores.loc[("S03", "end"), "total"])

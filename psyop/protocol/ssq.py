"""The Simulator Sickness Questionnaire (SSQ): its items, scale, subscale assignment and weights, in one place.

Kennedy, R. S., Lane, N. E., Berbaum, K. S. & Lilienthal, M. G. (1993). Simulator Sickness Questionnaire:
an enhanced method for quantifying simulator sickness. The International Journal of Aviation Psychology
3(3), 203-220. Sixteen symptoms, each rated 0-3 (none, slight, moderate, severe); each symptom counts
towards one or two of three subscales, nausea (N), oculomotor (O) and disorientation (D), seven symptoms
each (their Table 4). Scores: N = 9.54 x the sum of the N items' ratings, O = 7.58 x the O sum,
D = 13.92 x the D sum, total = 3.74 x (N sum + O sum + D sum) (raw sums, before weighting).

``session: questionnaires: [{name: ssq, when: ...}]`` shows these items (psyop.session.screens);
psyop.statistics.questionnaires scores them.
"""

from __future__ import annotations

NAME = "ssq"
TITLE = "Simulator Sickness Questionnaire"
#: the rating scale: 0..3
SCALE_LABELS: tuple[str, ...] = ("none", "slight", "moderate", "severe")

#: (symptom, the subscales it counts towards), in the published order (item 1 first)
ITEMS: tuple[tuple[str, frozenset[str]], ...] = (
    ("General discomfort", frozenset({"nausea", "oculomotor"})),
    ("Fatigue", frozenset({"oculomotor"})),
    ("Headache", frozenset({"oculomotor"})),
    ("Eyestrain", frozenset({"oculomotor"})),
    ("Difficulty focusing", frozenset({"oculomotor", "disorientation"})),
    ("Increased salivation", frozenset({"nausea"})),
    ("Sweating", frozenset({"nausea"})),
    ("Nausea", frozenset({"nausea", "disorientation"})),
    ("Difficulty concentrating", frozenset({"nausea", "oculomotor"})),
    ("Fullness of head", frozenset({"disorientation"})),
    ("Blurred vision", frozenset({"oculomotor", "disorientation"})),
    ("Dizzy (eyes open)", frozenset({"disorientation"})),
    ("Dizzy (eyes closed)", frozenset({"disorientation"})),
    ("Vertigo", frozenset({"disorientation"})),
    ("Stomach awareness", frozenset({"nausea"})),
    ("Burping", frozenset({"nausea"})),
)

SUBSCALES: tuple[str, ...] = ("nausea", "oculomotor", "disorientation")
#: each subscale's weight on the sum of its items' ratings
WEIGHTS: dict[str, float] = {"nausea": 9.54, "oculomotor": 7.58, "disorientation": 13.92}
#: the total's weight on the sum of the three raw subscale sums
TOTAL_WEIGHT = 3.74


def item_texts() -> tuple[str, ...]:
    """The 16 symptoms, in order."""
    return tuple(text for text, _ in ITEMS)


def subscale_items(subscale: str) -> tuple[int, ...]:
    """The 0-based item numbers that count towards ``subscale``.

    Examples
    --------
    >>> [n + 1 for n in subscale_items("nausea")]
    [1, 6, 7, 8, 9, 15, 16]
    >>> [len(subscale_items(s)) for s in SUBSCALES]
    [7, 7, 7]
    """
    if subscale not in WEIGHTS:
        raise KeyError(subscale)
    return tuple(i for i, (_, scales) in enumerate(ITEMS) if subscale in scales)

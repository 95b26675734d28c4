"""Protocols of shapes psyop does not ship, derived from protocols/detection.yaml and kept small (few
trials, two participants run them in seconds): a condition factor of words, numbers and words crossed,
and gaze validation with quality: rules (issue 41, item 5: figures, summaries and power must run on them)."""

from __future__ import annotations

import re
from pathlib import Path

DETECTION = Path(__file__).resolve().parents[1] / "protocols" / "detection.yaml"

#: the word factor every shape crosses with the level factor (the rendering mode of the test interval)
MODE_FACTOR = "    mode:\n      levels: [ocular, reversed]\n"

VALIDATION = """
gaze_validation:
  when: [start, end]
  points_deg: [[0, 0], [10, 0], [-10, 0]]
  settle_s: 0.2
  dwell_s: 0.3

quality:
  trials:
    - {measure: data_loss_share, max: 0.5, reason: the eye tracker lost the pupil}
  participants:
    - {measure: validation_mean_error_deg, max: VALIDATION_MAX, reason: poor tracker accuracy}
"""


def _replace(text: str, old: str, new: str) -> str:
    assert old in text, f"protocols/detection.yaml no longer holds {old!r}: update tests/unshipped_protocols.py"
    return text.replace(old, new)


def _small(text: str, name: str, repetitions: int) -> str:
    text = _replace(text, "  name: detection\n", f"  name: {name}\n")
    text = _replace(text, "  repetitions: 15 ", f"  repetitions: {repetitions} ")
    text = _replace(text, "      levels: [0, 0.25, 0.5, 0.75, 1] ", "      levels: [0, 0.25, 0.5, 1] ")
    return _replace(text, "test: {mode: ocular}", "test: {mode: {factor: mode}}")


#: protocols/detection.yaml's back-distance factor (its two lines, comment included)
BACK_FACTOR = re.compile(r"(?m)^    back_D:\n      levels: \[1, 2, 3\].*\n")


def _factors(text: str, new: str) -> str:
    text, n = BACK_FACTOR.subn(new, text)
    assert n == 1, "protocols/detection.yaml no longer has back_D: [1, 2, 3]: update tests/unshipped_protocols.py"
    return text


def word_factor(name: str = "words", repetitions: int = 4) -> str:
    """Thresholds over a factor of words only: ``mode: [ocular, reversed]`` instead of ``back_D`` (the back
    surface fixed at 2 D)."""
    text = _factors(_small(DETECTION.read_text(), name, repetitions), MODE_FACTOR)
    text = _replace(text, "depth: {factor: [back_D, level_D]}", "depth: {D: 2, factor: level_D}")
    return text.replace("depth: {factor: back_D}", "depth: {D: 2}")


def mixed_factors(name: str = "mixed", repetitions: int = 2) -> str:
    """Thresholds over numbers and words crossed: ``back_D: [1, 2]`` x ``mode: [ocular, reversed]``."""
    return _factors(_small(DETECTION.read_text(), name, repetitions), "    back_D:\n      levels: [1, 2]\n" + MODE_FACTOR)


def gaze_validation(name: str = "validated", repetitions: int = 4, validation_max_deg: float = 3.0) -> str:
    """:func:`word_factor` with a ``gaze_validation:`` at start and end and ``quality:`` rules, one of them on the
    validation's mean error (``validation_max_deg``)."""
    text = word_factor(name, repetitions)
    section = VALIDATION.replace("VALIDATION_MAX", f"{validation_max_deg:g}")
    return _replace(text, "\ndesign:\n", section + "\ndesign:\n")


SHAPES = {"words": word_factor, "mixed": mixed_factors, "validated": gaze_validation}


def write(directory: Path, shape: str, **kwargs: object) -> Path:
    """The protocol of ``shape`` (a key of :data:`SHAPES`) written to ``directory/<name>.yaml``."""
    text = SHAPES[shape](**kwargs)  # type: ignore[operator]
    name = next(line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("  name:"))
    path = directory / f"{name}.yaml"
    path.write_text(text)
    return path

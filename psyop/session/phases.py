"""One timed phase of a trial: what it shows, in which rendering mode, and what gaze does.

The session plan (psyop.session.plan) compiles a protocol's ``trial.phases`` into a tuple of
these; the loop runs them in order and then the response phase.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from psyop.session.rows import TrialRow
from psyop.optics.nodal import RenderingMode
from psyop.schedule.rows import interval_mode

RENDERING_MODES: tuple[str, ...] = tuple(m.value for m in RenderingMode)


@dataclass(frozen=True)
class PhaseSpec:
    """One timed phase.

    ``show``: 'cross' (drift recalibration target) | 'stimulus' (an interval) | 'blank' | 'off'
    (display off) | 'target' (a gaze validation target: psyop.session.validation.TargetPhase) | 'text' (a
    session screen's head-fixed text panel: psyop.session.screens.ScreenPhase). ``gaze``: 'cross', 'pursuit', 'fixate' (a static fixation target), 'free' or 'none' (what the observer looks at;
    drives simulated gaze). The rendering mode is the trial row's ``mode_column`` when given
    (intervals: ``mode_interval<k>``), else the fixed ``mode``. ``primitives``: the scene ids
    drawn (None: all of them). ``interval``: which interval's factor values the scene uses
    (1-based; 0: none). ``target_size_deg``: the recalibration cross's size. ``ends_after_s``: an
    interval with ``min_duration_s``: a live participant ends it with an answer input from this time into the
    phase on (its ``min_duration_s``), while ``duration_s`` is when a simulated participant ends it; None: the
    phase lasts ``duration_s`` for everyone.
    """

    name: str
    duration_s: float
    show: str
    gaze: str
    mode_column: str | None = None
    mode: str = "conventional"
    primitives: tuple[str, ...] | None = None
    interval: int = 0
    target_size_deg: float = 1.0
    ends_after_s: float | None = None

    def __post_init__(self) -> None:
        if self.show not in ("cross", "stimulus", "blank", "off", "target", "text"):
            raise ValueError(f"phase {self.name!r}: show must be cross, stimulus, blank, off, target or text, "
                             f"got {self.show!r}")
        if self.mode not in RENDERING_MODES:
            raise ValueError(f"phase {self.name!r}: unknown rendering mode {self.mode!r}")
        if self.mode_column is not None:
            match = re.fullmatch(r"mode_interval([1-9][0-9]*)", self.mode_column)
            if match is None or self.interval not in (0, int(match.group(1))):
                raise ValueError(f"phase {self.name!r}: mode_column must be mode_interval<k> (k = interval), "
                                 f"got {self.mode_column!r} with interval {self.interval}")
            object.__setattr__(self, "interval", int(match.group(1)))  # interval 0: taken from the column

    @property
    def renders(self) -> bool:
        return self.show in ("cross", "stimulus", "blank", "target", "text")

    @property
    def shows_scene(self) -> bool:
        """True when the phase draws scene primitives (an interval, or a blank with ``show:``)."""
        return self.show == "stimulus" or (self.show == "blank" and bool(self.primitives))


def mode_for(phase: PhaseSpec, row: TrialRow) -> str:
    """The rendering mode of ``phase`` in this trial: the one interval-to-mode rule.

    An interval's mode is the schedule's ``mode_interval<k>`` column, which the schedule
    compiler fills for every response kind (a reach study's ``modes:`` mapping is applied there);
    every other phase has its fixed ``mode`` (psyop.schedule.rows.interval_mode, also used by
    psyop.stimulus).
    """
    if phase.mode_column is None:
        return phase.mode
    return interval_mode(row, phase.interval)

"""The optional ``timing:`` section: what a trial whose intervals dropped frames becomes.

``timing: {max_dropped_frames: 2, on_violation: rerun}``: a trial whose stimulus phases (``show:
stimulus``, the intervals) dropped more display frames than ``max_dropped_frames`` (trials.parquet
``<phase>_dropped_frames``, counted by the session loop: docs/sessions.md "Timing") is

- ``rerun``: discarded and run again at the end of its block (as many as ``max_reruns`` times; the
  attempt after the last allowed rerun is kept, flagged), each discarded attempt recorded in
  session.json ``timing_reruns`` (trial, dropped frames, why), announced as a ``timing_rerun`` event and
  printed (one console line each); ``max_rerun_share``: a run that would discard more attempts than this
  share of the schedule's trials stops instead (exit 3, ``timing_stopped``, one line naming the rule and
  what to change; the attempt is discarded, the session resumable), rather than looping on a display that
  cannot keep the rule;
- ``flag``: kept, with ``timing_ok`` false.

A protocol without the section rules nothing (``timing_ok`` is null). docs/protocols.md "Timing".
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from psyop.protocol.base import Integer, Number, StrictModel


class TimingSection(StrictModel):
    """``timing:``: the most dropped frames a trial's intervals may have, and what a trial with more becomes."""

    max_dropped_frames: Integer = Field(ge=0, description="dropped display frames allowed over a trial's stimulus "
                                                          "phases (intervals)")
    on_violation: Literal["rerun", "flag"] = Field(
        description="rerun: run the trial again at the end of its block; flag: keep it with timing_ok false")
    max_reruns: Integer = Field(default=3, ge=0, description="rerun: times one trial may be run again; the attempt "
                                                             "after the last is kept, flagged")
    max_rerun_share: Number | None = Field(
        default=None, gt=0, le=1, description="rerun: the most attempts one run may discard, as a share of the "
                                              "schedule's trials; one more stops the session (exit 3, resumable)")

    @model_validator(mode="after")
    def _share_needs_rerun(self) -> TimingSection:
        if self.max_rerun_share is not None and self.on_violation != "rerun":
            raise ValueError("max_rerun_share limits reruns: use it with on_violation: rerun, or remove it")
        return self

    def rerun_limit(self, n_scheduled: int) -> int | None:
        """The most attempts one run may discard for a schedule of ``n_scheduled`` trials (None: no limit).

        >>> TimingSection(max_dropped_frames=0, on_violation="rerun", max_rerun_share=0.1).rerun_limit(104)
        10
        """
        if self.max_rerun_share is None:
            return None
        return math.floor(self.max_rerun_share * n_scheduled + 1e-9)

    def stop_message(self, limit: int, n_scheduled: int, reason: str) -> str:
        """The one line of a session this rule stopped: the rule, the last attempt's reason, what to change."""
        return (f"timing rule stopped the session: {limit} rerun(s) allowed in this run (timing.max_rerun_share "
                f"{self.max_rerun_share:g} of {n_scheduled} trials) and another attempt broke the rule ({reason}); "
                "the display cannot keep up: make it drop fewer frames (close other programs, a lower render "
                "scale) and run the same command to resume, or raise timing.max_dropped_frames (or use "
                "on_violation: flag) for a new --session")

    def violated(self, dropped_frames: int) -> bool:
        """Whether a trial whose intervals dropped ``dropped_frames`` frames breaks the rule."""
        return dropped_frames > self.max_dropped_frames

    def describe(self, dropped_frames: int) -> str:
        """Why a trial breaks the rule, in the words the log records."""
        return (f"its stimulus phases dropped {dropped_frames} display frame(s), more than timing.max_dropped_frames "
                f"= {self.max_dropped_frames}")

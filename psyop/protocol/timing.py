"""The optional ``timing:`` section: what a trial whose intervals dropped frames becomes.

``timing: {max_dropped_frames: 2, on_violation: rerun}``: a trial whose stimulus phases (``show:
stimulus``, the intervals) dropped more display frames than ``max_dropped_frames`` (trials.parquet
``<phase>_dropped_frames``, counted by the session loop: docs/sessions.md "Timing") is

- ``rerun``: discarded and run again at the end of its block (as many as ``max_reruns`` times; the
  attempt after the last allowed rerun is kept, flagged), each discarded attempt recorded in
  session.json ``timing_reruns`` (trial, dropped frames, why) and announced as a ``timing_rerun`` event;
- ``flag``: kept, with ``timing_ok`` false.

A protocol without the section rules nothing (``timing_ok`` is null). docs/protocols.md "Timing".
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from psyop.protocol.base import Integer, StrictModel


class TimingSection(StrictModel):
    """``timing:``: the most dropped frames a trial's intervals may have, and what a trial with more becomes."""

    max_dropped_frames: Integer = Field(ge=0, description="dropped display frames allowed over a trial's stimulus "
                                                          "phases (intervals)")
    on_violation: Literal["rerun", "flag"] = Field(
        description="rerun: run the trial again at the end of its block; flag: keep it with timing_ok false")
    max_reruns: Integer = Field(default=3, ge=0, description="rerun: times one trial may be run again; the attempt "
                                                             "after the last is kept, flagged")

    def violated(self, dropped_frames: int) -> bool:
        """Whether a trial whose intervals dropped ``dropped_frames`` frames breaks the rule."""
        return dropped_frames > self.max_dropped_frames

    def describe(self, dropped_frames: int) -> str:
        """Why a trial breaks the rule, in the words the log records."""
        return (f"its stimulus phases dropped {dropped_frames} display frame(s), more than timing.max_dropped_frames "
                f"= {self.max_dropped_frames}")

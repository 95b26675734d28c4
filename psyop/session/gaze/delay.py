"""Gaze the protocol delays on purpose (``display.added_latency_ms``, docs/latency.md).

:class:`DelayedGaze` wraps a gaze source. It passes every call through and keeps the samples the source
delivered (its raw stream, each :meth:`latest` call draining it, so :meth:`drain_raw` still hands the loop
every sample once, in order) for the last :data:`KEEP_S` seconds. :meth:`DelayedGaze.before` is the newest
kept sample at or before a time: the loop renders a frame with ``before(newest sample's time - added
latency)``, the sample held, not interpolated (a blink or a dropout that old is delayed too). Its age at
display is therefore the intrinsic age plus the added latency plus less than one tracker sample period.

What is kept is what the source delivers: a live tracker (LSL, Pupil) streams every sample; the simulated
tracker does so with ``observer: eye: {raw_stream: every_sample}``, while its default ``requested`` stream
holds only the samples frames asked for (one per frame: the delayed sample is then within a frame period,
not a tracker period, of the time asked for).
"""

from __future__ import annotations

import bisect
from typing import TYPE_CHECKING

from psyop.session.gaze.sample import GazeSample, GazeSource, RawGazeSample

if TYPE_CHECKING:
    from psyop.session.gaze.plan import FixationPlan
    from psyop.session.gaze.sync import ClockSync

#: how far back samples are kept, s (at least the largest added latency, psyop.protocol.display.MAX_ADDED_LATENCY_MS)
KEEP_S = 2.0


class DelayedGaze:
    """A :class:`~psyop.session.gaze.sample.GazeSource` whose past samples can be asked for (module docstring)."""

    def __init__(self, source: GazeSource, keep_s: float = KEEP_S) -> None:
        self.source = source
        self.keep_s = float(keep_s)
        self._pending: list[RawGazeSample] = []  # delivered, not yet drained by the loop's log
        self._t: list[float] = []  # the kept samples' times, ascending
        self._samples: list[GazeSample] = []

    # GazeSource --------------------------------------------------------------------
    def start(self) -> None:
        self.source.start()

    def close(self) -> None:
        self.source.close()

    def stats(self) -> dict[str, float | int]:
        return self.source.stats()

    def clock_sync(self) -> ClockSync | None:
        return self.source.clock_sync()

    def set_plan(self, plan: FixationPlan) -> None:
        self.source.set_plan(plan)

    def latest(self, now_s: float) -> GazeSample | None:
        sample = self.source.latest(now_s)
        self._take_raw()
        if sample is not None:
            self._keep(sample)
        return sample

    def drain_raw(self) -> list[RawGazeSample]:
        self._take_raw()
        samples, self._pending = self._pending, []
        return samples

    # the delay ---------------------------------------------------------------------
    def before(self, t_s: float) -> GazeSample | None:
        """The newest kept sample at or before ``t_s`` (None: none that old is kept)."""
        i = bisect.bisect_right(self._t, t_s + 1e-9) - 1
        return self._samples[i] if i >= 0 else None

    def _take_raw(self) -> None:
        raw = self.source.drain_raw()
        if not raw:
            return
        self._pending.extend(raw)
        for r in raw:
            self._keep(GazeSample(r.t_s, r.fixation_m, r.confidence, r.valid))

    def _keep(self, sample: GazeSample) -> None:
        t = sample.timestamp_s
        if t != t:  # NaN: no time, never asked for
            return
        if not self._t or t > self._t[-1]:
            self._t.append(t)
            self._samples.append(sample)
        else:
            i = bisect.bisect_left(self._t, t)
            if i < len(self._t) and self._t[i] == t:
                return  # the same sample again (latest() and the raw stream both deliver it)
            self._t.insert(i, t)
            self._samples.insert(i, sample)
        if len(self._t) > 64 and self._t[0] < self._t[-1] - 2.0 * self.keep_s:
            cut = bisect.bisect_left(self._t, self._t[-1] - self.keep_s)
            del self._t[:cut], self._samples[:cut]

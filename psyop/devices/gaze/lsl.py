"""Gaze from a Lab Streaming Layer stream (``--tracker lsl:NAME``; pip extra ``lsl`` brings pylsl).

The stream is resolved by name, else by type (``lsl:Gaze`` takes the first stream of type Gaze).
Its channels are read by label through a channel map (:mod:`psyop.devices.gaze.lsl_channels`):
detected from the labels (Pupil Capture's relay, Neon) or named (``lsl:NAME@neon``,
``lsl:NAME@MAP.json``).

Time: each sample's LSL timestamp is on the sender's LSL clock. ``inlet.time_correction()``
maps it onto this host's LSL clock, and a bracketed reading of ``pylsl.local_clock()`` against
the session clock maps that onto the session clock; both are re-measured every
``resync_every_s`` and the fit is what :meth:`LslGazeSource.clock_sync` returns (session.json
``runs[].clock_sync`` at the start, the summary's ``tracker.clock_sync_end`` at the end).

Honesty, as for the Pupil backend:

- the inlet is opened with ``recover=False``: liblsl's silent recovery loses the samples pushed
  while it reconnects without saying so. psyop notices the loss itself (``LostError``), counts a
  reconnect when the source comes back (same ``source_id``) and logs how long it was gone;
- a gap in the timestamps of more than 1.5 nominal sample periods is counted (``gaps``) with
  the total time missing (``gap_s``); an irregular-rate stream has no nominal period, so its
  gaps are not counted (stats say so);
- a stream whose timestamps step (some amplifiers; hyperscanning, where the sending host's
  clock moves) is detected, logged and re-anchored, never held stale: with ``d`` the
  sample-to-sample timestamp difference, ``a`` the local arrival interval (0 within a chunk),
  ``P`` the nominal period and ``T`` = ``clock_step_s`` (:data:`CLOCK_STEP_S`, 0.5 s), a regular
  stream has stepped when ``|d - P| > T`` and ``|d - a| > T`` (a real gap shows in the arrivals
  too, a backlog burst keeps ``d`` near ``P``); the step is ``d - P`` (``d - a`` when the arrivals
  had a gap as well). An irregular-rate stream has stepped when ``d < -T`` (stamps went back) or
  ``d - a > T`` (they advanced further than the time that passed); the step is ``d - a``. Each
  step moves the clock mapping by its size (:meth:`ClockSync.stepped`), so the sample that
  shows it and every later one map onto the session clock as before; it is counted
  (``clock_steps``), logged in ``events`` (``size_s``, ``direction`` back/forward) and the total
  in force is ``clock_step_offset_s``. A step of ``time_correction()`` itself by more than ``T``
  (the sender's clock moved: its stamps move with it) is absorbed into the same offset, so the
  mapping stays continuous whichever of the two is seen first (``correction_steps``, logged);
  slow drift is followed by the regular re-measurement as before. Steps under ``T`` are not
  detected (a backward one shows as older gaze, a forward one as younger);
- a sample with a non-finite or implausible fixation, a confidence below the threshold or a
  timestamp more than ``clock_jump_s`` from now (after any re-anchoring) is invalid (counted by
  reason);
- ``latest`` raises :class:`~psyop.session.gaze.sample.TrackerLost` after ``lost_after_s``
  without a sample: the session stops, every recorded trial and raw sample stays, and the
  session can be resumed.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from psyop.session.rows import JsonObject
from psyop.errors import UserError
from psyop.devices.gaze.lsl_channels import ChannelMap, detect_map, load_map
from psyop.session.gaze.plan import FixationPlan
from psyop.devices.gaze.pupil import world_mm_to_head_m, world_to_head_direction
from psyop.session.gaze.sample import EyeSample, GazeSample, RawBuffer, RawGazeSample, TrackerLost, is_usable
from psyop.session.gaze.sync import ClockSync

_NAN3 = (math.nan, math.nan, math.nan)

#: a timestamp step larger than this (s) is a clock step (module docstring), smaller ones are jitter
CLOCK_STEP_S = 0.5


def parse_spec(arg: str) -> tuple[str, str | None]:
    """(stream name or type, channel map or None) from ``NAME`` or ``NAME@MAP``.

    Examples
    --------
    >>> parse_spec("pupil_capture"), parse_spec("Phone_Neon Gaze@neon")
    (('pupil_capture', None), ('Phone_Neon Gaze', 'neon'))
    """
    name, _, map_spec = arg.partition("@")
    if not name:
        raise UserError("expected lsl:NAME (a stream name or type) or lsl:NAME@MAP", "--tracker")
    return name, (map_spec or None)


def stream_channels(info: Any) -> tuple[tuple[str, str | None], ...]:  # Any: pylsl.StreamInfo (pylsl is untyped)
    """(label, eye) of each channel of a full ``pylsl.StreamInfo`` (``desc/channels``); a stream
    without channel descriptions gets labels ``"0"``, ``"1"``, ..."""
    found: list[tuple[str, str | None]] = []
    channel = info.desc().child("channels").child("channel")
    while not channel.empty():
        eye = channel.child_value("eye")
        found.append((channel.child_value("label"), eye or None))
        channel = channel.next_sibling("channel")
    if len(found) != info.channel_count():
        return tuple((str(i), None) for i in range(info.channel_count()))
    return tuple(found)


class LslGazeSource:
    """A :class:`~psyop.session.gaze.sample.GazeSource` reading an LSL stream (module docstring)."""

    def __init__(self, name: str, *, clock: Callable[[], float], channel_map: str | None = None,
                 confidence_threshold: float = 0.6, lost_after_s: float = 1.0, resolve_timeout_s: float = 5.0,
                 resync_every_s: float = 1.0, clock_jump_s: float = 1.0,
                 clock_step_s: float = CLOCK_STEP_S) -> None:
        self.name = name
        self._clock = clock
        self._map_spec = channel_map
        self.confidence_threshold = confidence_threshold
        self.lost_after_s = lost_after_s
        self.resolve_timeout_s = resolve_timeout_s
        self.resync_every_s = resync_every_s
        self.clock_jump_s = clock_jump_s
        self.clock_step_s = clock_step_s
        self.map: ChannelMap | None = None
        self._index: dict[str, int] = {}
        self._inlet: Any = None  # Any: a pylsl.StreamInlet (untyped)
        self._source_id = ""
        self._period_s = math.nan
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._raw = RawBuffer()
        self._latest: GazeSample | None = None
        self._last_arrival_s = math.nan
        self._last_ts = math.nan
        self._sync: ClockSync | None = None
        self._corrections: list[float] = []
        self._lsl_minus_session_s = math.nan
        self._step_offset_s = 0.0  # the clock steps the mapping has absorbed so far (module docstring)
        self._counts = {"samples_received": 0, "gaps": 0, "reconnects": 0, "invalid_fixation": 0,
                        "invalid_low_confidence": 0, "invalid_time": 0, "sync_timeouts": 0, "lost": 0,
                        "clock_steps": 0, "correction_steps": 0}
        self._gap_s = 0.0
        self._events: list[dict[str, float | str]] = []
        self._error: str | None = None
        self._reconnect_from_s: float | None = None  # session time of the loss, until data comes back

    # connection --------------------------------------------------------------------------
    def _resolve(self, timeout_s: float) -> Any | None:  # Any: a pylsl.StreamInfo (untyped)
        import pylsl

        for prop in ("name", "type"):
            found = pylsl.resolve_byprop(prop, self.name, 1, timeout_s if prop == "name" else min(timeout_s, 1.0))
            if found:
                return found[0]
        return None

    def _open(self, info: Any) -> None:  # Any: a pylsl.StreamInfo (untyped)
        import pylsl

        inlet = pylsl.StreamInlet(info, max_buflen=30, recover=False)
        full = inlet.info(timeout=self.resolve_timeout_s)
        channels = stream_channels(full)
        where = f"{full.name()!r} (type {full.type()!r}, {full.channel_count()} channels)"
        chosen = load_map(self._map_spec) if self._map_spec else detect_map(channels)
        if chosen is None:
            labels = ", ".join(label + (f"[{eye}]" if eye else "") for label, eye in channels)
            raise UserError(f"LSL stream {where}: no built-in channel map fits its channels ({labels}); give one: "
                            "--tracker 'lsl:NAME@MAP.json' (docs/sessions.md)", "--tracker")
        self._index = chosen.resolve(channels, where)
        self.map = chosen
        srate = float(full.nominal_srate())
        self._period_s = 1.0 / srate if srate > 0 else math.nan
        self._source_id = full.source_id()
        inlet.open_stream(timeout=self.resolve_timeout_s)
        self._inlet = inlet

    def start(self) -> None:
        info = self._resolve(self.resolve_timeout_s)
        if info is None:
            raise UserError(f"no LSL stream named (or of type) {self.name!r} found within {self.resolve_timeout_s:g} s; "
                            "is the tracker's LSL outlet running on this network?", "--tracker", exit_code=3)
        self._open(info)
        self._resync(first=True)
        self._last_arrival_s = self._clock()
        self._thread = threading.Thread(target=self._receive, name="lsl-gaze", daemon=True)
        self._thread.start()

    # clock --------------------------------------------------------------------------------
    def _local_offset(self) -> float:
        """pylsl.local_clock() - session clock, from the tightest of a few bracketed readings."""
        import pylsl

        best = (math.inf, math.nan)
        for _ in range(5):
            t0 = self._clock()
            lsl_t = pylsl.local_clock()
            t1 = self._clock()
            best = min(best, (t1 - t0, lsl_t - 0.5 * (t0 + t1)))
        return best[1]

    def _resync(self, *, first: bool = False) -> None:
        import pylsl.util

        try:
            correction = float(self._inlet.time_correction(timeout=self.resolve_timeout_s if first else 0.5))
        except pylsl.util.TimeoutError:
            with self._lock:
                self._counts["sync_timeouts"] += 1
            if first:
                raise UserError(f"LSL stream {self.name!r}: no time_correction() estimate within "
                                f"{self.resolve_timeout_s:g} s", "--tracker", exit_code=3) from None
            return
        offset = self._local_offset()
        with self._lock:
            if self._corrections and abs(correction - self._corrections[-1]) > self.clock_step_s:
                # the sender's clock stepped against ours; its stamps step with it (seen as a timestamp
                # step before or after this): absorbed, so the mapping moves once, by the stamps' step
                step = correction - self._corrections[-1]
                self._step_offset_s += step
                self._counts["correction_steps"] += 1
                self._log_event("LSL time_correction stepped; absorbed into the clock mapping", size_s=step)
                self._corrections.clear()  # the spread of the estimates since the step, not across it
            self._corrections.append(correction)
            del self._corrections[:-60]
            sd = float(np.std(self._corrections)) if len(self._corrections) > 1 else 0.0
            # tracker (sender LSL) time = session time + (lsl_local - session) - correction (+ clock steps)
            sync = ClockSync(offset - correction + self._step_offset_s, 0.0, sd, math.nan, len(self._corrections),
                             "lsl-time-correction")
            self._sync = sync
            self._lsl_minus_session_s = offset

    # receiving ----------------------------------------------------------------------------
    def _receive(self) -> None:
        import pylsl.util

        next_sync = self._clock() + self.resync_every_s
        while not self._stop.is_set():
            try:
                if self._inlet is None:
                    self._reconnect()
                    continue
                # pull_chunk with a timeout waits out the whole timeout (up to max_samples): block on one
                # sample instead, then take whatever else is already there
                first, stamp = self._inlet.pull_sample(timeout=0.05)
                if first is not None:
                    samples, stamps = self._inlet.pull_chunk(timeout=0.0, max_samples=1024)
                    self._handle([first, *samples], [stamp, *stamps])
                if self._clock() >= next_sync:
                    next_sync = self._clock() + self.resync_every_s
                    self._resync()
            except pylsl.util.LostError:
                with self._lock:
                    # one outage, however often a stale resolver answer makes a new inlet fail again
                    if self._reconnect_from_s is None:
                        self._counts["lost"] += 1
                        self._reconnect_from_s = self._clock()
                        self._log_event("LSL stream lost; waiting for its source to come back")
                self._inlet = None
            except Exception as exc:  # noqa: BLE001 - reported by latest(), never a dead thread in silence
                with self._lock:
                    self._error = f"LSL gaze receiver failed: {exc.__class__.__name__}: {exc}"
                return

    def _reconnect(self) -> None:
        """Re-resolve the lost source (same ``source_id``) and open a new inlet; the reconnect is
        counted when its first sample arrives (a stale resolver answer opens an inlet that fails)."""
        import pylsl
        import pylsl.util

        while not self._stop.is_set():
            found = pylsl.resolve_byprop("source_id", self._source_id, 1, 0.2) if self._source_id else []
            if found:
                try:
                    inlet = pylsl.StreamInlet(found[0], max_buflen=30, recover=False)
                    inlet.open_stream(timeout=1.0)
                    self._inlet = inlet
                    self._resync(first=True)
                except (pylsl.util.LostError, pylsl.util.TimeoutError, UserError):
                    self._inlet = None
                    continue
                return

    def _value(self, sample: list[float], role: str) -> float:
        i = self._index.get(role)
        return float(sample[i]) if i is not None else math.nan

    def _eye(self, sample: list[float], eye: str) -> EyeSample | None:
        roles = [f"eye_centre_{eye}_{a}_mm" for a in "xyz"] + [f"gaze_normal_{eye}_{a}" for a in "xyz"] + \
            [f"pupil_diameter_{eye}_mm", f"pupil_diameter_{eye}_px"]
        if not any(r in self._index for r in roles):
            return None
        v = [self._value(sample, r) for r in roles]
        assert self.map is not None
        if self.map.fixation == "head_m":
            centre, normal = (v[0] / 1000.0, v[1] / 1000.0, v[2] / 1000.0), (v[3], v[4], v[5])
        else:  # Pupil world camera / Neon scene camera: x right, y down, z forward, mm
            centre, normal = world_mm_to_head_m((v[0], v[1], v[2])), world_to_head_direction((v[3], v[4], v[5]))
        return EyeSample(centre, normal, v[6], v[7])

    def _fixation(self, sample: list[float]) -> tuple[float, float, float]:
        m = self.map
        assert m is not None
        if m.fixation == "scene_px":
            assert m.scene is not None
            x, y = self._value(sample, "scene_x_px"), self._value(sample, "scene_y_px")
            if not (math.isfinite(x) and math.isfinite(y)):
                return _NAN3
            d = m.scene.direction_world(x, y)
            x_mm, y_mm, z_mm = (1000.0 * m.scene.distance_m * c for c in d)
            return world_mm_to_head_m((x_mm, y_mm, z_mm))
        point = (self._value(sample, "gaze_point_x"), self._value(sample, "gaze_point_y"),
                 self._value(sample, "gaze_point_z"))
        return world_mm_to_head_m(point) if m.fixation == "pupil_world_mm" else point

    def _step(self, ts: float, now: float) -> float | None:
        """The size of the clock step this timestamp shows (module docstring), or None."""
        d, a, limit = ts - self._last_ts, now - self._last_arrival_s, self.clock_step_s
        if not (math.isfinite(d) and math.isfinite(a)):
            return None
        period = self._period_s
        if math.isfinite(period):
            if abs(d - period) > limit and abs(d - a) > limit:
                return d - period if abs(a - period) <= limit else d - a
            return None
        return d - a if d < -limit or d - a > limit else None

    def _handle(self, samples: list[list[float]], stamps: list[float]) -> None:
        now = self._clock()
        with self._lock:
            sync = self._sync
        assert sync is not None
        for sample, ts in zip(samples, stamps, strict=True):
            ts = float(ts)
            step = self._step(ts, now)
            if step is not None:  # re-anchor: this sample and every later one map as if the clock had not moved
                with self._lock:
                    assert self._sync is not None
                    self._step_offset_s += step
                    self._sync = sync = self._sync.stepped(step)
                    self._counts["clock_steps"] += 1
                    self._log_event("LSL timestamps stepped; clock mapping re-anchored", size_s=step,
                                    direction="back" if step < 0 else "forward", tracker_t_s=ts)
            t_s = sync.to_local(ts)
            fixation = self._fixation(sample)
            confidence = self._value(sample, "confidence") if "confidence" in self._index else \
                (1.0 if all(math.isfinite(c) for c in fixation) else 0.0)
            finite = all(math.isfinite(c) for c in fixation) and math.isfinite(confidence)
            time_ok = math.isfinite(t_s) and abs(t_s - now) <= self.clock_jump_s
            valid = finite and time_ok and is_usable(fixation, confidence, self.confidence_threshold)
            self._raw.add(RawGazeSample(ts, t_s, now, valid, confidence, fixation,
                                        (self._value(sample, "norm_pos_x"), self._value(sample, "norm_pos_y")),
                                        self._eye(sample, "left"), self._eye(sample, "right")))
            with self._lock:
                c = self._counts
                if self._reconnect_from_s is not None:  # data again after a loss: the source is back
                    c["reconnects"] += 1
                    self._log_event("LSL stream reconnected", gone_s=now - self._reconnect_from_s)
                    self._reconnect_from_s = None
                c["samples_received"] += 1
                if not time_ok:
                    c["invalid_time"] += 1
                elif not finite or not is_usable(fixation, 1.0, 0.0):
                    c["invalid_fixation"] += 1  # non-finite, behind the eyes or beyond 100 km
                elif not valid:
                    c["invalid_low_confidence"] += 1
                if step is None and math.isfinite(self._last_ts) and math.isfinite(self._period_s) and \
                        ts - self._last_ts > 1.5 * self._period_s:
                    c["gaps"] += 1
                    self._gap_s += ts - self._last_ts - self._period_s
                self._last_ts = ts
                self._last_arrival_s = now
                self._latest = GazeSample(t_s if time_ok else now, fixation, confidence, valid)

    def _log_event(self, what: str, **values: float | str) -> None:
        """Record a stream event (caller holds the lock); the first 50 are kept."""
        if len(self._events) < 50:
            self._events.append({"t_s": self._clock(), "event": what, **values})

    # GazeSource ----------------------------------------------------------------------------
    def latest(self, now_s: float) -> GazeSample | None:
        with self._lock:
            silent_s = self._clock() - self._last_arrival_s
            sample, error = self._latest, self._error
        if error:
            raise TrackerLost(f"{error}; the session stops here and can be resumed")
        if silent_s > self.lost_after_s:
            raise TrackerLost(f"no gaze from LSL stream {self.name!r} for {silent_s:.1f} s (outlet closed or network "
                              "lost?); the session stops here and can be resumed")
        return sample

    def set_plan(self, plan: FixationPlan) -> None:
        """No-op: a real tracker measures where the eye looks."""
        return None

    def clock_sync(self) -> ClockSync | None:
        with self._lock:
            return self._sync

    def drain_raw(self) -> list[RawGazeSample]:
        """Every sample received since the last call, valid or not."""
        return self._raw.drain()

    def stats(self) -> JsonObject:
        with self._lock:
            sync = self._sync
            return {**self._counts, "gap_s": self._gap_s,
                    "gaps_counted": math.isfinite(self._period_s),
                    "nominal_rate_hz": 1.0 / self._period_s if math.isfinite(self._period_s) else None,
                    "channel_map": self.map.name if self.map else None,
                    "channel_map_note": self.map.note if self.map else None,
                    "raw_samples_dropped": self._raw.dropped,
                    "clock_sync_end": sync.as_dict() if sync is not None else None,
                    "clock_step_s": self.clock_step_s, "clock_step_offset_s": self._step_offset_s,
                    "events": list(self._events)}

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._inlet is not None:
            self._inlet.close_stream()
            self._inlet = None

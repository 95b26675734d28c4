"""``psyop run --lsl-markers``: the session's trial events as an LSL marker stream (pip extra ``lsl``).

One outlet per session: name ``psyop_markers``, type ``Markers``, irregular rate, four
``cf_string`` channels labelled ``event`` (``trial_start``, ``phase``, ``response``,
``trial_end``), ``trial`` (the trial index), ``condition`` and ``value`` (the phase name, the
raw answer or ``timeout``, the trial's duration in s). The stream's ``source_id`` is
``psyop:<study>:<participant>:<session>`` (LabRecorder re-finds it after a restart) and its
``desc/psyop`` holds study, participant, session, seed and protocol hash, so an XDF recording
says which session it is. Each marker is stamped with the event's session-clock time mapped onto
this host's LSL clock (``pylsl.local_clock()``, bracketed against the session clock at every
marker), so LabRecorder and pyxdf line it up with every other stream on the same clock.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from types import ModuleType

from psyop.session.rows import JsonMapping
from psyop.errors import UserError
from psyop.session.events import SessionEvent

CHANNELS = ("event", "trial", "condition", "value")
STREAM_NAME = "psyop_markers"


def _pylsl() -> ModuleType:
    try:
        import pylsl
    except (ImportError, OSError, RuntimeError) as exc:
        raise UserError(f"--lsl-markers needs pylsl ({exc.__class__.__name__}: {str(exc)[:120]}): "
                        "pip install 'psyop[lsl]'", "--lsl-markers") from exc
    return pylsl


class LslMarkerOutlet:
    """An :class:`~psyop.session.events.EventSink` publishing markers (module docstring)."""

    def __init__(self, identity: JsonMapping, clock: Callable[[], float]) -> None:
        pylsl = _pylsl()
        self._local_clock = pylsl.local_clock
        self._clock = clock
        source_id = f"psyop:{identity.get('study')}:{identity.get('participant')}:{identity.get('session')}"
        info = pylsl.StreamInfo(STREAM_NAME, "Markers", len(CHANNELS), pylsl.IRREGULAR_RATE, pylsl.cf_string, source_id)
        channels = info.desc().append_child("channels")
        for label in CHANNELS:
            channels.append_child("channel").append_child_value("label", label)
        described = info.desc().append_child("psyop")
        for key in ("study", "participant", "session", "seed", "protocol_sha256"):
            described.append_child_value(key, str(identity.get(key, "")))
        self._outlet = pylsl.StreamOutlet(info)
        self.n_sent = 0

    def wait_for_recorder(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for a consumer (LabRecorder, an inlet): markers pushed before one
        connects reach nobody. True when one is connected."""
        return bool(self._outlet.wait_for_consumers(timeout_s)) if timeout_s > 0 else bool(self._outlet.have_consumers())

    def lsl_time(self, t_s: float) -> float:
        """The LSL-clock time of session-clock time ``t_s`` (tightest of three bracketed readings)."""
        best = (math.inf, 0.0)
        for _ in range(3):
            t0 = self._clock()
            lsl_t = self._local_clock()
            t1 = self._clock()
            best = min(best, (t1 - t0, lsl_t - 0.5 * (t0 + t1)))
        return t_s + best[1]

    def emit(self, event: SessionEvent) -> None:
        value = f"{event.duration_s:.6f}" if event.kind == "trial_end" else event.value
        self._outlet.push_sample([event.kind, str(event.trial), event.condition, value], self.lsl_time(event.t_s))
        self.n_sent += 1

    def close(self, linger_s: float = 1.0) -> None:
        """Destroy the outlet, first lingering ``linger_s`` while a consumer is connected: liblsl sends
        asynchronously and an outlet destroyed at once drops what it has not sent yet (without the
        linger, tests/devices/test_lsl_markers.py lost the last trial_end marker)."""
        if self._outlet is not None and linger_s > 0 and self._outlet.have_consumers():
            time.sleep(linger_s)
        self._outlet = None

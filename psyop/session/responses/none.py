"""``--responses none``: nobody answers, so every response phase runs to its ``timeout_s``.

For dry runs of a protocol's timing and for testing how timed-out trials are logged and
analysed; a protocol without ``timeout_s`` is refused (the session would wait forever).
"""

from __future__ import annotations


from psyop.session.rows import TrialRow
from psyop.session.responses.base import Response


class NoResponses:
    needs_images = False

    def collect(self, row: TrialRow, now_s: float) -> Response | None:
        return None

    def timed_out(self) -> None:
        return None

    def close(self) -> None:
        return None

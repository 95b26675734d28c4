"""Session progress: a live bar on a terminal, a few plain lines otherwise.

On a TTY the bar (tqdm) redraws in place. Piped to a file or a CI log, redraws would be
kilobytes of carriage returns (about 22 kB for a 225-trial run), so there it prints a plain
line at the start, after every tenth of the trials, and at the end.
"""

from __future__ import annotations

import sys
from typing import Any, Protocol, TextIO


class Progress(Protocol):
    def set_postfix(self, **fields: Any) -> None: ...  # Any: tqdm's postfix values (numbers, text)

    def update(self, n: int = 1) -> None: ...

    def close(self) -> None: ...


class NoProgress:
    """Stands in for the progress bar when it is off. A disabled tqdm still takes tqdm's
    process-shared lock; a session killed (SIGKILL) while holding it would block every later
    bar in any process forked from the same parent (seen in the crash-safety test)."""

    def set_postfix(self, **_: Any) -> None:  # Any: as ProgressBar.set_postfix
        return None

    def update(self, _: int = 1) -> None:
        return None

    def close(self) -> None:
        return None


class PlainLines:
    """Occasional plain progress lines: start, every ``step`` trials, end."""

    def __init__(self, total: int, initial: int, desc: str, stream: TextIO, parts: int = 10) -> None:
        self.total, self.done, self.desc, self.stream = total, initial, desc, stream
        self.step = max(1, -(-total // parts))
        self._postfix = ""
        self._last_printed = -1
        self._print()

    def _print(self) -> None:
        print(f"{self.desc}: {self.done}/{self.total} trials{self._postfix}", file=self.stream, flush=True)
        self._last_printed = self.done

    def set_postfix(self, **fields: Any) -> None:  # Any: as ProgressBar.set_postfix
        self._postfix = " (" + ", ".join(f"{k} {v}" for k, v in fields.items()) + ")" if fields else ""

    def update(self, n: int = 1) -> None:
        before = self.done
        self.done += n
        if self.done // self.step > before // self.step and self.done < self.total:
            self._postfix = ""
            self._print()

    def close(self) -> None:
        if self._last_printed != self.done:
            self._postfix = ""
            self._print()


def session_progress(total: int, initial: int, desc: str, *, enabled: bool, stream: TextIO | None = None) -> Progress:
    """The progress display of one session: off, a live bar (TTY) or plain lines."""
    if not enabled:
        return NoProgress()
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    if isatty is not None and isatty():
        from tqdm import tqdm

        return tqdm(total=total, initial=initial, file=stream, unit="trial", dynamic_ncols=True, desc=desc)
    return PlainLines(total, initial, desc, stream)

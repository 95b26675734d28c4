"""Per-trial durable append: checksummed records + session lock vs the plain Arrow IPC stream.

Each trial appends its frame table (a 2 s + 0.5 s + 2 s trial at 90 Hz: 405 frames) and its
trial row, each made durable (fdatasync) before the next trial, as ``SessionStore.append_trial``
does. The baseline is the writer psyop used before the checksummed log (``pa.ipc.new_stream``,
``write_batch``, flush, fdatasync), reproduced here. Both run interleaved in one process on
the same disk; the claim is the ratio of medians. Without fsync the ratio isolates the CPU
cost of framing and CRC32.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from psyop.session.log.layout import SessionPaths
from psyop.session.log.schema import FRAME_SCHEMA, trial_schema
from psyop.session.log.store import SessionStore


class _LegacyWriter:
    """The pre-checksum segment writer (an Arrow IPC stream, fsynced per append)."""

    def __init__(self, path: Path, schema: pa.Schema, fsync: bool) -> None:
        self._file = open(path, "xb")  # noqa: SIM115
        self._writer = pa.ipc.new_stream(self._file, schema)
        self.schema = schema
        self._fsync = fsync

    def append(self, table: pa.Table) -> None:
        if table.schema != self.schema:
            table = table.select(self.schema.names).cast(self.schema)
        for batch in table.to_batches():
            self._writer.write_batch(batch)
        self._file.flush()
        if self._fsync:
            os.fdatasync(self._file.fileno())

    def close(self) -> None:
        self._writer.close()
        self._file.close()


def _schedule(n: int) -> pd.DataFrame:
    return pd.DataFrame({"trial": range(n), "block": 0, "condition": "c", "trial_seed": range(n),
                         "back_D": 1.0, "level_D": 0.25, "correct_interval": 1})


def _frames(trial: int, n_frames: int = 405) -> pa.Table:
    columns = {}
    for field in FRAME_SCHEMA:
        if pa.types.is_floating(field.type):
            columns[field.name] = np.random.default_rng(trial).random(n_frames)
        elif pa.types.is_integer(field.type):
            columns[field.name] = np.full(n_frames, trial) if field.name == "trial" else np.arange(n_frames)
        elif pa.types.is_boolean(field.type):
            columns[field.name] = np.ones(n_frames, dtype=bool)
        else:
            columns[field.name] = ["interval1"] * n_frames
    return pa.table(columns, schema=FRAME_SCHEMA)


def _time_new(root: Path, schedule: pd.DataFrame, rows: list[dict], frames: list[pa.Table], fsync: bool) -> list[float]:
    store = SessionStore(SessionPaths(root, "bench", "B1", 1), trial_schema(schedule), fsync=fsync)
    store.open({"study": "bench", "seed": 1, "n_trials_scheduled": len(rows)})
    times = []
    for row, frame in zip(rows, frames):
        start = time.perf_counter()
        store.append_trial(row, frame)
        times.append(time.perf_counter() - start)
    store.close()
    return times


def _time_old(root: Path, schedule: pd.DataFrame, rows: list[dict], frames: list[pa.Table], fsync: bool) -> list[float]:
    root.mkdir(parents=True, exist_ok=True)
    schema = trial_schema(schedule)
    trials = _LegacyWriter(root / "trials.arrows", schema, fsync)
    frame_writer = _LegacyWriter(root / "frames.arrows", FRAME_SCHEMA, fsync)
    times = []
    for row, frame in zip(rows, frames):
        start = time.perf_counter()
        frame_writer.append(frame)
        record = {name: [row.get(name)] for name in schema.names}
        trials.append(pa.Table.from_pydict(record, schema=schema))
        times.append(time.perf_counter() - start)
    trials.close()
    frame_writer.close()
    return times


def run(out_dir: Path, quick: bool) -> str:
    n_trials = 40 if quick else 225
    repeats = 3 if quick else 5
    schedule = _schedule(n_trials)
    rows = [{**r, "response": "1", "correct": True, "trial_start_s": 1.0, "trial_end_s": 5.0}
            for r in schedule.to_dict("records")]
    frames = [_frames(t) for t in range(n_trials)]
    results: dict[tuple[str, bool], list[float]] = {}
    lock_s: list[float] = []
    with tempfile.TemporaryDirectory(prefix="psyop-bench-log-", dir=out_dir if out_dir.exists() else None) as tmp:
        for rep in range(repeats):
            for fsync in (True, False):
                for name, fn in (("old", _time_old), ("new", _time_new)):  # interleaved
                    root = Path(tmp) / f"{name}-{fsync}-{rep}"
                    results.setdefault((name, fsync), []).extend(fn(root, schedule, rows, frames, fsync))
            store = SessionStore(SessionPaths(Path(tmp) / f"lock-{rep}", "bench", "B1", 1), trial_schema(schedule))
            start = time.perf_counter()
            store.lock.acquire()
            lock_s.append(time.perf_counter() - start)
            store.lock.release()

    def med_ms(name: str, fsync: bool) -> float:
        return statistics.median(results[(name, fsync)]) * 1e3

    lines = [
        "## Session log: per-trial durable append, checksummed + locked vs plain Arrow IPC",
        "",
        f"{n_trials} trials x {repeats} repeats, interleaved; per trial one 405-row frame table and one trial row, "
        "each fdatasync'ed (as `SessionStore.append_trial`). Median ms per trial.",
        "",
        "| fsync | old (Arrow IPC stream) ms | new (CRC32 records + lock) ms | new / old |",
        "|---|---|---|---|",
    ]
    for fsync in (True, False):
        old, new = med_ms("old", fsync), med_ms("new", fsync)
        lines.append(f"| {'on' if fsync else 'off'} | {old:.3f} | {new:.3f} | {new / old:.2f} |")
    lines += ["", f"Taking the session lock (once per run): median {statistics.median(lock_s) * 1e3:.3f} ms.", ""]
    lines += _largest_design_memory(out_dir, quick)
    return "\n".join(lines)


def _largest_design_memory(out_dir: Path, quick: bool) -> list[str]:
    """Peak RSS of `psyop validate` / `psyop compile` on the largest design accepted
    (100 000 conditions x 10 repetitions = the 1 million trial cap)."""
    import re
    import subprocess
    import sys

    repo = Path(__file__).resolve().parents[1]
    if quick:
        return ["Largest accepted design: skipped in --quick.", ""]
    text = (repo / "protocols" / "detection.yaml").read_text()
    text = text.replace("levels: [1, 2, 3]", "levels: {start: 0.5, step: 0.001, count: 20000}", 1)
    text = re.sub(r"(?m)^(\s*repetitions:).*$", r"\g<1> 10", text, count=1)
    rows = ["| command | peak RSS MB | wall s |", "|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="psyop-bench-design-") as tmp:
        protocol = Path(tmp) / "largest.yaml"
        protocol.write_text(text)
        for name, extra in (("validate", []), ("compile", ["--seed", "1", "--out", str(Path(tmp) / "s.parquet")])):
            # each in a fresh interpreter that reports its own peak RSS (ru_maxrss, kB on Linux)
            code = ("import resource, sys; from psyop.cli import main; rc = main(sys.argv[1:]); "
                    "print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr); sys.exit(rc)")
            start = time.perf_counter()
            done = subprocess.run([sys.executable, "-c", code, name, str(protocol), *extra],
                                  capture_output=True, text=True, check=True)
            wall = time.perf_counter() - start
            kb = int(done.stderr.rsplit("MAXRSS", 1)[1].split()[0])
            rows.append(f"| psyop {name} (100 000 conditions x 10 repetitions) | {kb / 1024:.0f} | {wall:.1f} |")
    return ["### Largest accepted design", "", *rows, ""]

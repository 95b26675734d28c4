"""Where one ``psyop power`` replication spends its CPU time, per stage, for each shipped study.

One replication (seed 0, replication 0) per shipped protocol at the paper's sample size
(detection/discrimination 6, ordinal/realism 19, egocentric 13; ``--quick``: 2 participants), run
in this process after a warm-up replication (imports and caches are not counted). Each stage is
the CPU time (``time.process_time``, this process's threads) spent *inside* the named call less
the time of the named calls nested in it (exclusive time), measured by wrapping the calls for the
duration of the run only:

- compile: ``parse_protocol`` + ``apply_effects`` + ``compile_plan`` + ``compile_schedule``
- session set-up: the rest of ``run_session`` (backends, metadata, store opening ...)
- trial loop: ``TrialLoop.run`` less the log writes in it
- log writes: the store's ``open``, ``append_trial``, ``append_gaze``, ``update_metadata``
- finalise: the store's ``finalise`` (salvage, parquet, session.json)
- load: ``load_dataset`` (the durable path), or building the analysis table from the in-memory log
- fits: ``fit_psychometric_table`` (two-interval studies)
- tests: the rest of ``study_tests`` (ANOVA, regressions, binomial tests, mixed models)
- other: the replication's total less all of the above

Both the full path (:func:`psyop.power.replicate.run_replication_durable`: durable logs finalised
to parquet and read back by ``load_dataset``) and the replication path ``psyop power`` runs
(:func:`psyop.power.replicate.run_replication`: the same ``run_session`` loop into an in-memory log)
are measured, and their outcomes must be identical (the benchmark fails otherwise).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the paper's sample size per shipped study
PAPER_N = {"detection": 6, "discrimination": 6, "ordinal": 19, "egocentric": 13, "realism": 19}
STAGES = ("compile", "session set-up", "trial loop", "log writes", "finalise", "load", "fits", "tests", "other")


class StageClock:
    """Exclusive CPU time per stage of nested wrapped calls."""

    def __init__(self) -> None:
        self.totals = dict.fromkeys(STAGES, 0.0)
        self._stack: list[list[float]] = []  # [start, nested time] per open call

    def wrap(self, stage: str, function: Callable) -> Callable:
        def timed(*args, **kwargs):
            self._stack.append([time.process_time(), 0.0])
            try:
                return function(*args, **kwargs)
            finally:
                start, nested = self._stack.pop()
                elapsed = time.process_time() - start
                self.totals[stage] += elapsed - nested
                if self._stack:
                    self._stack[-1][1] += elapsed
        return timed


@contextlib.contextmanager
def _patched(clock: StageClock) -> Iterator[None]:
    import psyop.schedule.compile as schedule
    from psyop import protocol
    from psyop.power import effects, memory_log, study_tests
    from psyop.run import runner
    from psyop.session.log.store import SessionStore
    from psyop.session.loop import TrialLoop
    from psyop.statistics import dataset, psychometric

    targets = [(protocol, "parse_protocol", "compile"), (effects, "apply_effects", "compile"),
               (runner, "compile_plan", "compile"), (schedule, "compile_schedule", "compile"),
               (runner, "run_session", "session set-up"), (TrialLoop, "run", "trial loop"),
               (dataset, "load_dataset", "load"), (memory_log, "analysis_trials", "load"),
               (psychometric, "fit_psychometric_table", "fits"), (study_tests, "study_tests", "tests")]
    for store in (SessionStore, memory_log.MemoryLog):
        targets += [(store, "open", "log writes"), (store, "append_trial", "log writes"),
                    (store, "append_gaze", "log writes"), (store, "update_metadata", "log writes"),
                    (store, "finalise", "finalise")]
    saved = [(owner, name, owner.__dict__[name]) for owner, name, _ in targets]
    try:
        for owner, name, stage in targets:
            setattr(owner, name, clock.wrap(stage, owner.__dict__[name]))
        yield
    finally:
        for owner, name, original in saved:
            setattr(owner, name, original)


def measure(function: Callable, task) -> tuple[dict[str, float], object]:
    """Stage CPU times of ``function(task)`` and its result."""
    clock = StageClock()
    with _patched(clock):
        start = time.process_time()
        result = function(task)
        total = time.process_time() - start
    clock.totals["other"] = total - sum(clock.totals.values())
    return {**clock.totals, "total": total}, result


def run(out_dir: Path, quick: bool) -> str:
    from psyop.power.study_tests import same_outcomes
    from psyop.power.replicate import (
        ReplicationTask,
        run_replication,
        run_replication_durable,
    )

    lines = [
        "## One power replication, CPU seconds per stage (bench_power_stages)",
        "",
        "One replication (seed 0) per shipped study at the paper's size, in one process after a warm-up",
        "replication; exclusive CPU time per stage (module docstring). `full`: durable session logs, finalised",
        "to parquet and read back by load_dataset (the path before issue 30); `replication`: the path",
        "`psyop power` runs (the same run_session loop into an in-memory log, the same analysis calls).",
        "Both give the same outcomes (checked: every p value identical, a refused test NaN on both with the same note).",
        "",
        "| study | N | path | " + " | ".join(STAGES) + " | total |",
        "|---|---:|---|" + "---:|" * (len(STAGES) + 1),
    ]
    for name, n in PAPER_N.items():
        n = 2 if quick else n
        path = ROOT / "protocols" / f"{name}.yaml"
        warm = ReplicationTask(path.read_text(), str(path), (), 2, 99, 0)
        run_replication_durable(warm), run_replication(warm)
        task = ReplicationTask(path.read_text(), str(path), (), n, 0, 0)
        rows = {}
        for label, function in (("full", run_replication_durable), ("replication", run_replication)):
            rows[label] = measure(function, task)
        full, replication = rows["full"][1], rows["replication"][1]
        if not (full.participants, full.replication, full.n_trials) == (
                replication.participants, replication.replication, replication.n_trials) or not same_outcomes(
                full.outcomes, replication.outcomes):
            raise AssertionError(f"bench_power_stages: {name}: the replication path's outcomes differ from the full "
                                 "path's on the same task")
        for label, (stages, _) in rows.items():
            lines.append(f"| {name} | {n} | {label} | " + " | ".join(f"{stages[s]:.2f}" for s in STAGES)
                         + f" | **{stages['total']:.2f}** |")
    return "\n".join(lines)

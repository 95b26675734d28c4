"""Run the analysis steps of a make dry run in one process: ``make figures`` imports the statistics
stack (psignifit, statsmodels, pingouin, scipy, matplotlib) once, not once per script.

    python analysis/batch.py [--jobs N] make -n --no-print-directory figures-all STUDIES_MK=results/.studies.mk

make still decides what is out of date: its dry run (the command given, run with
``ANALYSE=__analyse__`` added) lists, in build order, the recipe of every target to rebuild and of
every target downstream of one. This then runs that list. A recipe line
``__analyse__ analysis/NAME.py ARGS`` runs NAME's ``main`` in this process exactly as
``python analysis/NAME.py ARGS`` does (same argv, same outputs; each script stays runnable alone);
any other recipe line (``echo``, ``mkdir -p``) runs in bash, as make would run it.

``--jobs N`` (figures.mk passes ``$(JOBS)``) runs the plan in up to N worker processes: the plan is cut
into its independent parts (:func:`independent_parts`: steps that share no target, by make's rules, stay
in one part, in make's order), the parts run side by side, each in a worker that imports the stack once,
and each part's output is printed whole, in the plan's order, when it is done (as ``make -O``). The
collectors run last, in this process. ``--jobs 1`` (or a plan of one part) runs everything here, in order.

One study's failure does not stop the others (as ``make -k`` with figures.mk's ``.DELETE_ON_ERROR``):
a step that fails has its target (its ``--out``) deleted if the step changed it and its error said in
one line; every step whose target depends on a failed (or skipped) target, by make's own rules (its
database, ``make -p -q``), is skipped with one line saying why; every other step still runs. The
summary (``analysis/results_table.py``) collects what the others built: it runs even when some
study failed, told which (``PSYOP_FAILED_STUDIES``), and says so instead of reading their old
results. At the end each failure is listed again, one line each, and the exit status is 2.
"""

from __future__ import annotations

import multiprocessing
import os
import runpy
import shlex
import subprocess
import sys
import tempfile
import traceback
from types import TracebackType
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

#: what the dry run's recipes say instead of ``$(PY)`` (figures.mk: ``ANALYSE ?= $(PY)``)
MARK = "__analyse__"
#: make's exit status when a recipe failed
FAILED_EXIT = 2
#: scripts that collect every study's results: run even when some study failed (told which, in
#: :data:`FAILED_STUDIES_ENV`), as a summary of what was built
COLLECTORS = frozenset({"results_table.py"})
#: the environment variable naming (comma-separated) the studies whose analysis failed in this run
FAILED_STUDIES_ENV = "PSYOP_FAILED_STUDIES"


@dataclass(frozen=True)
class Step:
    """One analysis script run: ``python SCRIPT ARGV...``."""

    script: Path
    argv: tuple[str, ...]

    @property
    def target(self) -> Path | None:
        """The file the step builds (its ``--out``), None when it names none."""
        for i, arg in enumerate(self.argv):
            if arg == "--out" and i + 1 < len(self.argv):
                return Path(self.argv[i + 1])
            if arg.startswith("--out="):
                return Path(arg.removeprefix("--out="))
        return None

    @property
    def study(self) -> str | None:
        """The study the step analyses (its ``--study``), None when it names none."""
        for i, arg in enumerate(self.argv):
            if arg == "--study" and i + 1 < len(self.argv):
                return self.argv[i + 1]
            if arg.startswith("--study="):
                return arg.removeprefix("--study=")
        return None


def parse_plan(text: str) -> list[Step | str]:
    """The dry run's recipe lines, in order: a :class:`Step` for each analysis script, the shell
    line itself for anything else.

    Examples
    --------
    >>> plan = parse_plan('mkdir -p figures\\n__analyse__ analysis/supp_linearity.py --out "figures/s.png"\\n')
    >>> plan[0], plan[1].script.as_posix(), plan[1].target.as_posix()
    ('mkdir -p figures', 'analysis/supp_linearity.py', 'figures/s.png')
    """
    plan: list[Step | str] = []
    for line in text.splitlines():
        if not line.strip():
            continue
        words = shlex.split(line)
        if words[0] == MARK:
            if len(words) < 2:
                raise ValueError(f"a recipe runs {MARK} without a script: {line!r}")
            plan.append(Step(Path(words[1]), tuple(words[2:])))
        else:
            plan.append(line)
    return plan


def run_script(step: Step) -> int:
    """Run ``step``'s script as ``__main__`` in this process; its exit status (a traceback, as
    Python prints it, is status 1)."""
    import matplotlib.pyplot as plt

    saved_argv, saved_path = sys.argv, list(sys.path)
    sys.argv = [str(step.script), *step.argv]
    sys.path.insert(0, str(step.script.parent))  # as `python analysis/NAME.py`: its folder first
    try:
        with warnings.catch_warnings():  # a script's warning filters end with it
            runpy.run_path(str(step.script), run_name="__main__")
    except SystemExit as done:
        if done.code is None or isinstance(done.code, int):
            return done.code or 0
        print(done.code, file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - a bug: one line naming it and where; the script alone gives the traceback
        print(f"{step.script.name}: internal error: {_where(exc)}{type(exc).__name__}: {exc} (run it alone for the "
              f"traceback: python {shlex.join([str(step.script), *step.argv])})", file=sys.stderr)
        return 1
    finally:
        sys.argv = saved_argv
        sys.path[:] = saved_path
        plt.close("all")  # a script that failed half-way leaves no figure for the next one
    return 0


def _stamp(path: Path | None) -> tuple[int, int] | None:
    try:
        return None if path is None else (os.stat(path).st_mtime_ns, os.stat(path).st_size)
    except FileNotFoundError:
        return None


def _delete_if_changed(target: Path | None, before: tuple[int, int] | None) -> None:
    if target is not None and target.exists() and _stamp(target) != before:
        print(f"batch.py: *** Deleting file '{target}'", file=sys.stderr)
        target.unlink()


def _where(exc: BaseException) -> str:
    """'study_figures.py:59: ' (the innermost frame of ``exc``'s traceback), '' without one."""
    tb: TracebackType | None = exc.__traceback__
    frames = traceback.extract_tb(tb) if tb is not None else []
    return f"{Path(frames[-1].filename).name}:{frames[-1].lineno}: " if frames else ""


def prerequisites(make_argv: Sequence[str]) -> dict[str, set[str]]:
    """Every target's prerequisites, by make's database (``make -p -q``: runs nothing); {} when it cannot be read."""
    argv = [a for a in make_argv if a not in ("-n", "--dry-run", "--just-print", "--recon")]
    done = subprocess.run([*argv, "-p", "-q", f"ANALYSE={MARK}"], capture_output=True, text=True)
    rules: dict[str, set[str]] = {}
    for line in done.stdout.splitlines():
        if not line or line[0] in "#\t " or ":" not in line or "=" in line.split(":", 1)[0]:
            continue
        target, _, rest = line.partition(":")
        if rest.startswith(("=", ":")):
            continue  # a variable (`X := ...`) or a double-colon rule
        rules.setdefault(target.strip(), set()).update(p for p in rest.split() if p != "|")
    return rules


@dataclass
class _Run:
    """What a run of the plan has done so far: the failed and skipped targets, each failure's line."""

    rules: dict[str, set[str]]
    broken: set[str] = field(default_factory=set)
    failures: list[str] = field(default_factory=list)
    failed_studies: list[str] = field(default_factory=list)

    def blocked_by(self, step: Step) -> set[str]:
        """The failed or skipped targets ``step``'s target depends on (by make's rules or its arguments)."""
        needs = set(self.rules.get(str(step.target), set())) if step.target is not None else set()
        needs |= {a for a in step.argv if a in self.broken}
        return needs & self.broken

    def fail(self, step: Step, status: int) -> None:
        what = f"study {step.study}: " if step.study else ""
        self.failures.append(f"{what}{step.script.name} -> {step.target or '(no --out)'} (exit {status})")
        if step.study and step.study not in self.failed_studies:
            self.failed_studies.append(step.study)
        if step.target is not None:
            self.broken.add(str(step.target))

    def merge(self, other: _Run) -> None:
        """Add what ``other`` (a part run elsewhere) failed and skipped."""
        self.broken |= other.broken
        self.failures += other.failures
        self.failed_studies += [s for s in other.failed_studies if s not in self.failed_studies]


def _run_shell(line: str, state: _Run) -> None:
    sys.stdout.flush()
    status = subprocess.run(["bash", "-c", line]).returncode
    if status:
        print(f"batch.py: *** [{line}] Error {status}", file=sys.stderr)
        state.failures.append(f"[{line}] (exit {status})")


def _run_step(step: Step, state: _Run) -> None:
    blocked = state.blocked_by(step)
    if blocked and step.script.name not in COLLECTORS:
        print(f"batch.py: skipped {step.target or step.script} ({step.script.name}): it needs "
              f"{', '.join(sorted(blocked))}, which failed above", file=sys.stderr)
        if step.target is not None:
            state.broken.add(str(step.target))
        return
    target = step.target
    before = _stamp(target)
    os.environ[FAILED_STUDIES_ENV] = ",".join(state.failed_studies)
    try:
        status = run_script(step)
    except KeyboardInterrupt:
        _delete_if_changed(target, before)
        raise
    finally:
        os.environ.pop(FAILED_STUDIES_ENV, None)
    sys.stdout.flush()
    if status:
        print(f"batch.py: *** [{target or step.script}] Error {status} ({step.script})", file=sys.stderr)
        _delete_if_changed(target, before)
        state.fail(step, status)


def _run_entry(entry: Step | str, state: _Run) -> None:
    if isinstance(entry, str):
        _run_shell(entry, state)
    else:
        _run_step(entry, state)


def independent_parts(plan: Sequence[Step | str],
                      rules: dict[str, set[str]]) -> tuple[list[list[Step | str]], list[Step | str]]:
    """``plan`` cut into parts that can run side by side, and the tail that runs after them all.

    A step and the shell lines before it are one item. Two items are in one part when one's target is a
    prerequisite of the other's (by ``rules``, make's, or among its arguments), or when they analyse the same
    study (they read the same sessions: the first measures their gaze quality, the others read it from the
    cache), directly or through other items. Each part keeps make's order. The collectors
    (:data:`COLLECTORS`) with their shell lines, and the shell lines after the last step, are the tail: they
    read what every part built.

    Examples
    --------
    >>> plan = parse_plan("__analyse__ a.py --study x --out r/x.csv\\n__analyse__ b.py --out f/m.png\\n"
    ...                   "__analyse__ c.py --study x --out f/x.png\\n__analyse__ results_table.py --out r/s.md\\n")
    >>> parts, tail = independent_parts(plan, {})
    >>> [[s.script.name for s in part] for part in parts], [s.script.name for s in tail]
    ([['a.py', 'c.py'], ['b.py']], ['results_table.py'])
    """
    items: list[list[Step | str]] = []
    tail: list[Step | str] = []
    pending: list[Step | str] = []
    for entry in plan:
        if isinstance(entry, str):
            pending.append(entry)
            continue
        if entry.script.name in COLLECTORS:
            tail += [*pending, entry]
        else:
            items.append([*pending, entry])
        pending = []
    tail += pending
    joined = list(range(len(items)))

    def root(i: int) -> int:
        while joined[i] != i:
            i = joined[i]
        return i

    owner: dict[str, int] = {}  # a target, or "study:NAME", -> the first item that builds or reads it
    for i, item in enumerate(items):
        step = item[-1]
        assert isinstance(step, Step)
        own = {str(step.target)} | ({f"study:{step.study}"} if step.study else set())
        for key in sorted(rules.get(str(step.target), set()) | set(step.argv) | own):
            if key in owner:
                joined[root(i)] = root(owner[key])
        for key in own:
            owner.setdefault(key, i)
    parts: dict[int, list[Step | str]] = {}
    for i, item in enumerate(items):
        parts.setdefault(root(i), []).extend(item)
    return list(parts.values()), tail


def _run_part(part: Sequence[Step | str], rules: dict[str, set[str]]) -> tuple[bytes, bytes, _Run]:
    """Run ``part`` in order (in a worker process): its standard output and error, captured, and what failed."""
    state = _Run(rules)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = os.dup(1), os.dup(2)
        os.dup2(out.fileno(), 1)  # the scripts' prints and the shell lines' output alike
        os.dup2(err.fileno(), 2)
        try:
            for entry in part:
                _run_entry(entry, state)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            for fd, kept in zip((1, 2), saved):
                os.dup2(kept, fd)
                os.close(kept)
        out.seek(0)
        err.seek(0)
        return out.read(), err.read(), _Run({}, state.broken, state.failures, state.failed_studies)


def _platform_start_method() -> None:
    """In a worker: the platform's default start method for the scripts' own pools (a spawned worker
    inherits "spawn", under which a script's process pool would start fresh interpreters that import the
    whole stack again), so that a script runs as it does alone."""
    multiprocessing.set_start_method(None, force=True)


def _run_parts(parts: list[list[Step | str]], state: _Run, jobs: int) -> None:
    """Run ``parts`` side by side in up to ``jobs`` worker processes (each a fresh interpreter); print each
    part's output whole, in order, and merge what it failed into ``state``."""
    context = multiprocessing.get_context("spawn")  # no forked copy of this process's threads or figures
    with ProcessPoolExecutor(max_workers=min(jobs, len(parts)), mp_context=context,
                             initializer=_platform_start_method) as pool:
        runs = [pool.submit(_run_part, part, state.rules) for part in parts]
        for part, run in zip(parts, runs):
            try:
                out, err, done = run.result()
            except Exception as exc:  # noqa: BLE001 - a worker that died (killed, out of memory): its steps failed
                names = [str(s.target or s.script) for s in part if isinstance(s, Step)]
                out, err = b"", f"batch.py: *** a worker stopped ({type(exc).__name__}: {exc})\n".encode()
                done = _Run({}, set(names), [f"{', '.join(names)} (the worker stopped)"], [])
            sys.stdout.buffer.write(out)
            sys.stdout.flush()
            sys.stderr.buffer.write(err)
            sys.stderr.flush()
            state.merge(done)


def run_plan(plan: Sequence[Step | str], rules: dict[str, set[str]] | None = None, jobs: int = 1) -> int:
    """Run every step; a failed step's changed target is deleted and the steps that depend on it (``rules``:
    make's prerequisites) are skipped, the others run; 2 when anything failed. ``jobs`` > 1: the plan's
    :func:`independent_parts` side by side in up to ``jobs`` processes, then its tail here; else all here, in order."""
    state = _Run(rules or {})
    parts, tail = independent_parts(plan, state.rules) if jobs > 1 else ([], list(plan))
    if len(parts) > 1:
        _run_parts(parts, state, jobs)
    else:
        tail = list(plan)
    for entry in tail:
        _run_entry(entry, state)
    if not state.failures:
        return 0
    print(f"batch.py: {len(state.failures)} step(s) failed (the others ran):", file=sys.stderr)
    for line in state.failures:
        print(f"batch.py: *** {line}", file=sys.stderr)
    return FAILED_EXIT


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    jobs = 1
    if argv[:1] == ["--jobs"]:
        if len(argv) < 2 or not argv[1].isdigit() or int(argv[1]) < 1:
            print(f"batch.py: --jobs takes a whole number of processes >= 1, not {argv[1:2] or 'nothing'}; "
                  "e.g. --jobs 2", file=sys.stderr)
            return FAILED_EXIT
        jobs, argv = int(argv[1]), argv[2:]
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else FAILED_EXIT
    dry_run = subprocess.run([*argv, f"ANALYSE={MARK}"], capture_output=True, text=True)
    if dry_run.returncode:
        sys.stderr.write(dry_run.stderr)
        return dry_run.returncode
    sys.stderr.write(dry_run.stderr)
    plan = parse_plan(dry_run.stdout)
    return run_plan(plan, prerequisites(argv) if plan else {}, jobs)


if __name__ == "__main__":
    sys.exit(main())

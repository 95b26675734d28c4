"""Run the analysis steps of a make dry run in one process: ``make figures`` imports the statistics
stack (psignifit, statsmodels, pingouin, scipy, matplotlib) once, not once per script.

    python analysis/batch.py make -n --no-print-directory figures-all STUDIES_MK=results/.studies.mk

make still decides what is out of date: its dry run (the command given, run with
``ANALYSE=__analyse__`` added) lists, in build order, the recipe of every target to rebuild and of
every target downstream of one. This then runs that list. A recipe line
``__analyse__ analysis/NAME.py ARGS`` runs NAME's ``main`` in this process exactly as
``python analysis/NAME.py ARGS`` does (same argv, same outputs; each script stays runnable alone);
any other recipe line (``echo``, ``mkdir -p``) runs in bash, as make would run it.

One study's failure does not stop the others (as ``make -k`` with figures.mk's ``.DELETE_ON_ERROR``):
a step that fails has its target (its ``--out``) deleted if the step changed it and its error said in
one line; every step whose target depends on a failed (or skipped) target, by make's own rules (its
database, ``make -p -q``), is skipped with one line saying why; every other step still runs. The
summary (``analysis/results_table.py``) collects what the others built: it runs even when some
study failed, told which (``PSYOP_FAILED_STUDIES``), and says so instead of reading their old
results. At the end each failure is listed again, one line each, and the exit status is 2.
"""

from __future__ import annotations

import os
import runpy
import shlex
import subprocess
import sys
import traceback
from types import TracebackType
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
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
    broken: set[str]
    failures: list[str]
    failed_studies: list[str]

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


def run_plan(plan: Sequence[Step | str], rules: dict[str, set[str]] | None = None) -> int:
    """Run every step in order; a failed step's changed target is deleted and the steps that depend on
    it (``rules``: make's prerequisites) are skipped, the others run; 2 when anything failed."""
    state = _Run(rules or {}, set(), [], [])
    for step in plan:
        if isinstance(step, str):
            _run_shell(step, state)
        else:
            _run_step(step, state)
    if not state.failures:
        return 0
    print(f"batch.py: {len(state.failures)} step(s) failed (the others ran):", file=sys.stderr)
    for line in state.failures:
        print(f"batch.py: *** {line}", file=sys.stderr)
    return FAILED_EXIT


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else FAILED_EXIT
    dry_run = subprocess.run([*argv, f"ANALYSE={MARK}"], capture_output=True, text=True)
    if dry_run.returncode:
        sys.stderr.write(dry_run.stderr)
        return dry_run.returncode
    sys.stderr.write(dry_run.stderr)
    plan = parse_plan(dry_run.stdout)
    return run_plan(plan, prerequisites(argv) if plan else {})


if __name__ == "__main__":
    sys.exit(main())

"""Run the analysis steps of a make dry run in one process: ``make figures`` imports the statistics
stack (psignifit, statsmodels, pingouin, scipy, matplotlib) once, not once per script.

    python analysis/batch.py make -n --no-print-directory figures-all STUDIES_MK=results/.studies.mk

make still decides what is out of date: its dry run (the command given, run with
``ANALYSE=__analyse__`` added) lists, in build order, the recipe of every target to rebuild and of
every target downstream of one. This then runs that list. A recipe line
``__analyse__ analysis/NAME.py ARGS`` runs NAME's ``main`` in this process exactly as
``python analysis/NAME.py ARGS`` does (same argv, same outputs; each script stays runnable alone);
any other recipe line (``echo``, ``mkdir -p``) runs in bash, as make would run it. As make with
figures.mk's ``.DELETE_ON_ERROR``: the first step that fails stops the run, its target (its
``--out``) is deleted if the step changed it, and the exit status is 2.
"""

from __future__ import annotations

import os
import runpy
import shlex
import subprocess
import sys
import traceback
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

#: what the dry run's recipes say instead of ``$(PY)`` (figures.mk: ``ANALYSE ?= $(PY)``)
MARK = "__analyse__"
#: make's exit status when a recipe failed
FAILED_EXIT = 2


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
    except Exception:  # noqa: BLE001 - what `python script.py` would do: the traceback, status 1
        traceback.print_exc()
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


def run_plan(plan: Sequence[Step | str]) -> int:
    """Run every step in order; stop at the first failure (its changed target deleted)."""
    for step in plan:
        if isinstance(step, str):
            sys.stdout.flush()
            status = subprocess.run(["bash", "-c", step]).returncode
            if status:
                print(f"batch.py: *** [{step}] Error {status}", file=sys.stderr)
                return FAILED_EXIT
            continue
        target = step.target
        before = _stamp(target)
        try:
            status = run_script(step)
        except KeyboardInterrupt:
            _delete_if_changed(target, before)
            raise
        sys.stdout.flush()
        if status:
            print(f"batch.py: *** [{target or step.script}] Error {status} ({step.script})", file=sys.stderr)
            _delete_if_changed(target, before)
            return FAILED_EXIT
    return 0


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
    return run_plan(parse_plan(dry_run.stdout))


if __name__ == "__main__":
    sys.exit(main())

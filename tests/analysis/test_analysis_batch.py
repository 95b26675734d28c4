"""analysis/batch.py: the steps of a make dry run, run in one process (or, --jobs N, their independent parts
in N worker processes), build what one process per script builds (byte for byte), only what make finds out
of date, and fail as make does with .DELETE_ON_ERROR (the changed target deleted, what depends on it
skipped, the rest run, exit 2)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BATCH = ROOT / "analysis" / "batch.py"


def _makefile(tmp: Path, extra: str = "") -> Path:
    makefile = tmp / "Makefile"
    makefile.write_text(
        f"ANALYSE ?= {sys.executable}\nOUT ?= out\n"
        f"$(OUT)/linearity.png: {ROOT}/analysis/supp_linearity.py\n\t@mkdir -p $(OUT)\n\t@echo \"[psyop] $@\"\n"
        "\t@$(ANALYSE) $< --out $@\n"
        f"$(OUT)/parallax.png: {ROOT}/analysis/fig03_parallax_vs_eccentricity.py $(OUT)/linearity.png\n"
        "\t@echo \"[psyop] $@\"\n\t@$(ANALYSE) $< --out $@\n" + extra)
    return makefile


def _env() -> dict[str, str]:
    return {**os.environ, "SOURCE_DATE_EPOCH": "0", "MPLBACKEND": "Agg"}  # the PDFs carry the same date


def _batch(tmp: Path, *targets: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(BATCH), "make", "-n", "-s", "--no-print-directory", *targets],
                          cwd=tmp, env=_env(), capture_output=True, text=True, timeout=300)


def test_batch_builds_what_one_process_per_script_builds_and_only_what_is_out_of_date(tmp_path: Path) -> None:
    _makefile(tmp_path)
    alone = subprocess.run(["make", "-s", "OUT=alone", "alone/parallax.png"], cwd=tmp_path, env=_env(),
                           capture_output=True, text=True, timeout=300)
    assert alone.returncode == 0, alone.stderr
    batched = _batch(tmp_path, "out/parallax.png")
    assert batched.returncode == 0, batched.stderr
    assert batched.stdout.splitlines() == ["[psyop] out/linearity.png", "[psyop] out/parallax.png"]
    for name in ("linearity.png", "linearity.pdf", "parallax.png", "parallax.pdf"):
        assert (tmp_path / "out" / name).read_bytes() == (tmp_path / "alone" / name).read_bytes(), name

    assert _batch(tmp_path, "out/parallax.png").stdout == ""  # up to date: nothing runs
    later = (tmp_path / "out" / "parallax.png").stat().st_mtime + 10
    os.utime(tmp_path / "out" / "linearity.png", (later, later))  # a newer prerequisite: only its dependant
    assert _batch(tmp_path, "out/parallax.png").stdout.splitlines() == ["[psyop] out/parallax.png"]


def test_a_failing_step_deletes_its_changed_target_skips_what_depends_on_it_and_the_rest_runs(tmp_path: Path) -> None:
    """As make -k with .DELETE_ON_ERROR: one study's failure does not stop the others (issue 41)."""
    bad = tmp_path / "bad.py"
    bad.write_text("import sys\nfrom pathlib import Path\nPath(sys.argv[sys.argv.index('--out') + 1]).write_text('half')\n"
                   "sys.exit(1)\n")
    _makefile(tmp_path, f"out/half.png: {bad}\n\t@mkdir -p out\n\t@$(ANALYSE) $< --study broken --out $@\n"
                        "out/after.png: out/half.png out/parallax.png\n\t@$(ANALYSE) " f"{ROOT}/analysis/supp_linearity.py --out $@\n"
                        "all: out/after.png out/parallax.png\n")
    done = _batch(tmp_path, "all")
    assert done.returncode == 2
    assert "Deleting file 'out/half.png'" in done.stderr and "Error 1" in done.stderr, done.stderr
    assert not (tmp_path / "out" / "half.png").exists() and not (tmp_path / "out" / "after.png").exists()
    assert "skipped out/after.png (supp_linearity.py): it needs out/half.png, which failed above" in done.stderr
    assert (tmp_path / "out" / "parallax.png").is_file()  # independent of the failed step: built
    assert done.stderr.splitlines()[-1] == "batch.py: *** study broken: bad.py -> out/half.png (exit 1)"


def test_a_script_that_crashes_is_one_line_naming_the_error_and_the_others_run(tmp_path: Path) -> None:
    crash = tmp_path / "crash.py"
    crash.write_text("import sys\n'a' + 1.5\n")
    _makefile(tmp_path, f"out/crash.png: {crash}\n\t@mkdir -p out\n\t@$(ANALYSE) $< --study words --out $@\n"
                        "all: out/crash.png out/parallax.png\n")
    done = _batch(tmp_path, "all")
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "crash.py: internal error: crash.py:2: TypeError: can only concatenate str" in done.stderr
    assert (tmp_path / "out" / "parallax.png").is_file() and (tmp_path / "out" / "linearity.png").is_file()


def test_the_summary_runs_after_a_failed_study_and_leaves_it_out(tmp_path: Path) -> None:
    """results_table.py (a collector) runs though a study failed, told which (PSYOP_FAILED_STUDIES): its old
    results are not read, and the summary says it was not analysed."""
    sys.path.insert(0, str(ROOT / "analysis"))
    try:
        import batch
    finally:
        sys.path.remove(str(ROOT / "analysis"))
    seen = {}

    def fake_run(step):
        seen[step.script.name] = os.environ.get(batch.FAILED_STUDIES_ENV)
        return 2 if step.script.name == "fit_psychometric.py" else 0

    plan = batch.parse_plan("__analyse__ analysis/fit_psychometric.py --study words --out r/words_fits.csv\n"
                            "__analyse__ analysis/fig_detection_thresholds.py --study words --fits r/words_fits.csv "
                            "--out f/words.png\n"
                            "__analyse__ analysis/fig_realism.py --study realism --out f/realism.png\n"
                            "__analyse__ analysis/results_table.py --out r/summary.md\n")
    rules = {"f/words.png": {"r/words_fits.csv"}, "r/summary.md": {"f/words.png", "f/realism.png"}}
    original = batch.run_script
    batch.run_script = fake_run
    try:
        assert batch.run_plan(plan, rules) == batch.FAILED_EXIT
    finally:
        batch.run_script = original
    assert seen == {"fit_psychometric.py": "", "fig_realism.py": "words", "results_table.py": "words"}


def test_a_plan_that_cannot_be_made_runs_nothing(tmp_path: Path) -> None:
    _makefile(tmp_path)
    done = _batch(tmp_path, "out/parallax.png", "out/no-rule.png")
    assert done.returncode == 2 and "No rule to make target" in done.stderr
    assert not (tmp_path / "out").exists()


def _probe(tmp: Path, name: str) -> Path:
    """A script that writes its --out and prints its process id."""
    script = tmp / name
    script.write_text("import os, sys\nfrom pathlib import Path\nout = Path(sys.argv[sys.argv.index('--out') + 1])\n"
                      "out.parent.mkdir(parents=True, exist_ok=True)\nout.write_text(os.environ.get('PSYOP_FAILED_STUDIES', ''))\n"
                      "print(f'{out.name} pid', os.getpid())\n")
    return script


def test_jobs_run_independent_parts_in_other_processes_each_part_whole_in_order(tmp_path: Path) -> None:
    """--jobs 2: the plan's independent parts (here: the two model figures, a probe of study x) run in worker
    processes, each part's output whole in the plan's order; the collector runs last, in batch.py's own process.
    (bench_figures_vs_c57032f checks every figure and table of the paper-sized build byte for byte against the
    former code, which ran them in one process.)"""
    probe, collector = _probe(tmp_path, "probe.py"), _probe(tmp_path, "results_table.py")
    _makefile(tmp_path, f"$(OUT)/x.txt: {probe}\n\t@echo \"[psyop] $@\"\n\t@$(ANALYSE) $< --study x --out $@\n"
                        f"$(OUT)/summary.md: {collector} $(OUT)/x.txt $(OUT)/parallax.png\n\t@$(ANALYSE) $< --out $@\n"
                        "all: $(OUT)/summary.md\n")
    batch = subprocess.Popen([sys.executable, str(BATCH), "--jobs", "2", "make", "-n", "-s", "--no-print-directory",
                              "all"], cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = batch.communicate(timeout=300)
    assert batch.returncode == 0, err
    lines = out.splitlines()
    assert [line.split(" pid")[0] for line in lines] == ["[psyop] out/x.txt", "x.txt", "[psyop] out/linearity.png",
                                                         "[psyop] out/parallax.png", "summary.md"]  # make's order
    assert int(lines[1].split()[-1]) != batch.pid and int(lines[4].split()[-1]) == batch.pid
    assert all((tmp_path / "out" / name).stat().st_size > 0 for name in ("linearity.pdf", "parallax.png"))
    assert (tmp_path / "out" / "x.txt").read_text() == "" and (tmp_path / "out" / "summary.md").read_text() == ""


def test_jobs_a_failing_part_deletes_its_target_and_the_others_and_the_summary_run(tmp_path: Path) -> None:
    """--jobs 2, as --jobs 1: the failed step's changed target is deleted and listed, the independent part is
    built, and the collector, run last, is told which study failed."""
    bad = tmp_path / "bad.py"
    bad.write_text("import sys\nfrom pathlib import Path\nPath(sys.argv[sys.argv.index('--out') + 1]).write_text('half')\n"
                   "print('bad ran', file=sys.stderr)\nsys.exit(1)\n")
    collector = _probe(tmp_path, "results_table.py")
    _makefile(tmp_path, f"out/half.png: {bad}\n\t@mkdir -p out\n\t@$(ANALYSE) $< --study broken --out $@\n"
                        f"out/summary.md: {collector} out/half.png out/parallax.png\n\t@$(ANALYSE) $< --out $@\n"
                        "all: out/summary.md\n")
    done = subprocess.run([sys.executable, str(BATCH), "--jobs", "2", "make", "-n", "-s", "--no-print-directory", "all"],
                          cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert "bad ran" in done.stderr and "Deleting file 'out/half.png'" in done.stderr, done.stderr
    assert not (tmp_path / "out" / "half.png").exists() and (tmp_path / "out" / "parallax.png").is_file()
    assert (tmp_path / "out" / "summary.md").read_text() == "broken"
    assert done.stderr.splitlines()[-1] == "batch.py: *** study broken: bad.py -> out/half.png (exit 1)"


def test_jobs_must_be_a_whole_number(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(BATCH), "--jobs", "two", "make", "-n"], cwd=tmp_path, env=_env(),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and done.stderr.strip() == (
        "batch.py: --jobs takes a whole number of processes >= 1, not ['two']; e.g. --jobs 2")

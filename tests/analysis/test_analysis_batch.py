"""analysis/batch.py: the steps of a make dry run, run in one process, build what one process per
script builds (byte for byte), only what make finds out of date, and fail as make does with
.DELETE_ON_ERROR (the changed target deleted, nothing after it run, exit 2)."""

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


def test_a_failing_step_deletes_its_changed_target_and_stops_the_run(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("import sys\nfrom pathlib import Path\nPath(sys.argv[sys.argv.index('--out') + 1]).write_text('half')\n"
                   "sys.exit(1)\n")
    _makefile(tmp_path, f"out/half.png: {bad}\n\t@mkdir -p out\n\t@$(ANALYSE) $< --out $@\n"
                        "out/after.png: out/half.png out/parallax.png\n\t@$(ANALYSE) " f"{ROOT}/analysis/supp_linearity.py --out $@\n")
    done = _batch(tmp_path, "out/after.png")
    assert done.returncode == 2
    assert "Deleting file 'out/half.png'" in done.stderr and "Error 1" in done.stderr, done.stderr
    assert not (tmp_path / "out" / "half.png").exists() and not (tmp_path / "out" / "after.png").exists()


def test_a_plan_that_cannot_be_made_runs_nothing(tmp_path: Path) -> None:
    _makefile(tmp_path)
    done = _batch(tmp_path, "out/parallax.png", "out/no-rule.png")
    assert done.returncode == 2 and "No rule to make target" in done.stderr
    assert not (tmp_path / "out").exists()

"""Analysis outputs under a full disk: figures and results are whole or absent, the error is one
line with exit 2, make deletes what a failed recipe touched, and a fit cache that cannot be read
is rebuilt instead of failing every later build."""

from __future__ import annotations

import errno
import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.atomic import stale_temp_files
from psyop.statistics import simulate as sim
from psyop.statistics.dataset import write_dataset

ROOT = Path(__file__).resolve().parents[2]
ANALYSIS = ROOT / "analysis"


def _script(name: str):
    if str(ANALYSIS) not in sys.path:
        sys.path.insert(0, str(ANALYSIS))
    return importlib.import_module(name)


@pytest.fixture
def data(tmp_path: Path) -> Path:
    rng = np.random.default_rng(3)
    root = tmp_path / "data"
    write_dataset(root, {"detection": sim.simulate_detection(rng, n_subjects=2),
                         "realism": sim.simulate_realism(rng, n_subjects=4)}, simulated=True)
    return root


def test_a_full_disk_while_drawing_leaves_no_truncated_figure(tmp_path: Path, data: Path,
                                                              monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    common = _script("_common")
    realism = _script("fig_realism")
    out = tmp_path / "figures" / "realism.png"
    argv = ["--data", str(data), "--results", str(tmp_path / "results"), "--out", str(out)]
    assert common.run(lambda: realism.main(argv)) == 0
    before = out.read_bytes(), out.with_suffix(".pdf").read_bytes()
    capsys.readouterr()

    def full(*args: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    assert common.run(lambda: realism.main(argv)) == 2
    monkeypatch.undo()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "No space left on device" in err, err
    assert str(tmp_path / "results") in err or str(out.parent) in err
    assert (out.read_bytes(), out.with_suffix(".pdf").read_bytes()) == before  # the old figures, whole
    assert stale_temp_files(out.parent) == [] and stale_temp_files(tmp_path / "results") == []


@pytest.mark.parametrize("damage", ["empty", "half-written", "binary"])
def test_an_unreadable_fit_cache_is_rebuilt(tmp_path: Path, data: Path, capsys: pytest.CaptureFixture[str],
                                           damage: str) -> None:
    common = _script("_common")
    fit_args = ("--n-jobs", "1", "--n-bootstrap", "50")
    fresh = tmp_path / "fresh_fits.csv"
    fit = _script("fit_psychometric").main
    assert fit(["--study", "detection", "--data", str(data), "--out", str(fresh),
                                             *fit_args]) == 0
    cache = tmp_path / "results" / "detection_fits.csv"
    cache.parent.mkdir()
    text = fresh.read_text()
    cache.write_bytes({"empty": b"", "half-written": text[: len(text) // 3].split("\n")[0].encode() + b"\n1,2",
                       "binary": b"\x00\xff\xfe" * 100}[damage])
    capsys.readouterr()
    fits = common.read_fits(cache, data=data, study="detection", fit_args=fit_args, rebuild=fit)
    assert "rebuilding it" in capsys.readouterr().err
    pd.testing.assert_frame_equal(fits, common.read_fits(fresh))
    with pytest.raises(Exception) as caught:  # without the data to rebuild from: one located error
        cache.write_bytes(b"")
        common.read_fits(cache)
    assert type(caught.value).__name__ == "UserError" and str(cache) in str(caught.value)


def test_make_deletes_the_target_of_a_failed_recipe(tmp_path: Path) -> None:
    """figures.mk's .DELETE_ON_ERROR, with make itself: a recipe that writes half a target and fails."""
    makefile = tmp_path / "Makefile"
    makefile.write_text(f"include {ROOT / 'figures.mk'}\n\nhalf.png:\n\tprintf 'trunc' > $@; exit 1\n")
    done = subprocess.run(["make", "-f", str(makefile), "half.png"], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode != 0
    assert "Deleting file" in done.stderr, done.stderr
    assert not (tmp_path / "half.png").exists()


@pytest.mark.parametrize("script", ["fig03_parallax_vs_eccentricity", "supp_linearity"])
def test_model_figures_on_a_full_disk_are_one_line(tmp_path: Path, script: str) -> None:
    """The two optics figures did not go through _common.run: a full disk was an OSError traceback
    (run on their own and inside make figures' batch)."""
    out = tmp_path / "figures" / f"{script}.png"
    fault = ("import errno, os, runpy, sys\n"
             "def full(*a):\n    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))\n"
             "os.fsync = full\n"
             f"sys.argv = [{str(ANALYSIS / (script + '.py'))!r}, '--out', {str(out)!r}]\n"
             f"sys.path.insert(0, {str(ANALYSIS)!r})\n"
             "runpy.run_path(sys.argv[0], run_name='__main__')\n")
    done = subprocess.run([sys.executable, "-c", fault], capture_output=True, text=True, cwd=ROOT,
                          env=dict(os.environ, MPLBACKEND="Agg"))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert "No space left on device" in done.stderr and not out.exists()


#: the analysis/ files that are modules, not scripts (imported by the scripts, or make's runner)
MODULES = {"_common.py", "_twoafc.py", "_confidence.py", "paper_values.py", "batch.py"}
SCRIPTS = sorted(p.name for p in ANALYSIS.glob("*.py") if p.name not in MODULES)


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_analysis_script_runs_through_common_run(name: str) -> None:
    """Every script's entry point is `sys.exit(run(main))` (analysis/_common.run: a UserError or an
    OSError is one line and exit 2): the two optics figures were not, so a full disk was a traceback."""
    text = (ANALYSIS / name).read_text()
    main_block = text.split('if __name__ == "__main__":', 1)
    assert len(main_block) == 2, f"{name}: no __main__ block"
    assert main_block[1].strip() == "sys.exit(run(main))", f"{name}: {main_block[1].strip()!r}"
    assert "from _common import" in text and " run" in text.split("from _common import", 1)[1].split("\n", 1)[0]


#: every script that writes without fitting anything slow, with the arguments that reach its writes
#: (a study script needs the data fixture's sessions; {data}, {results}, {out} are filled in);
#: results_table.py needs the others' results first and is covered by the static test above
WRITERS = {
    "fig03_parallax_vs_eccentricity.py": ["--out", "{out}.png"],
    "supp_linearity.py": ["--out", "{out}.png"],
    "fig_realism.py": ["--data", "{data}", "--results", "{results}", "--out", "{out}.png"],
    "fit_psychometric.py": ["--data", "{data}", "--results", "{results}", "--out", "{out}.csv", "--n-jobs", "1",
                            "--n-bootstrap", "20", "--grid-scale", "0.5"],
}


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EROFS])
@pytest.mark.parametrize("name", sorted(WRITERS))
def test_a_failing_disk_is_one_line_in_every_writing_script(tmp_path: Path, data: Path, name: str,
                                                            code: int) -> None:
    out = tmp_path / "out dir" / name.removesuffix(".py")
    args = [a.format(data=data, results=tmp_path / "results", out=out) for a in WRITERS[name]]
    fault = ("import errno, os, runpy, sys\n"
             f"def broken(*a):\n    raise OSError({code}, os.strerror({code}))\n"
             "os.fsync = broken\n"
             f"sys.argv = [{str(ANALYSIS / name)!r}, *{args!r}]\n"
             f"sys.path.insert(0, {str(ANALYSIS)!r})\n"
             "runpy.run_path(sys.argv[0], run_name='__main__')\n")
    done = subprocess.run([sys.executable, "-c", fault], capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env=dict(os.environ, MPLBACKEND="Agg"))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert os.strerror(code) in done.stderr and name in done.stderr, done.stderr
    assert not list(out.parent.glob(f"{out.name}*")) if out.parent.exists() else True

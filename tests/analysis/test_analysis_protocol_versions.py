"""Two protocol versions in one study: `make figures` analyses each apart (``<study>@<hash12>``, results
named by the short hash, the summary says so); a script given the whole study refuses it unless pooled on
purpose, and the pooling is stated."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.errors import UserError
from psyop.statistics import simulate as sim
from psyop.statistics.dataset import write_dataset

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"


def _script(name: str):
    if str(ANALYSIS) not in sys.path:
        sys.path.insert(0, str(ANALYSIS))
    return importlib.import_module(name)


def _realism():
    return _script("fig_realism")


@pytest.fixture()
def two_versions(tmp_path):
    data = tmp_path / "data"
    table = sim.simulate_realism(np.random.default_rng(3), n_subjects=4)
    write_dataset(data, {"realism": table}, simulated=True, protocol_sha256={"realism": "a" * 64})
    for path in sorted(data.glob("realism/sub-*/ses-*/session.json"))[:2]:
        meta = json.loads(path.read_text())
        meta["protocol_sha256"] = "b" * 64  # these participants' sessions ran the second version (e.g. 20 repetitions)
        path.write_text(json.dumps(meta))
    return data, tmp_path / "results"


def test_sessions_of_two_protocol_versions_are_refused_naming_both_hashes(two_versions):
    data, results = two_versions
    with pytest.raises(UserError, match=r"2 protocol versions \(sha256 aaaaaaaaaaaa, bbbbbbbbbbbb\).*--pool-protocols"):
        _realism().main(["--data", str(data), "--results", str(results), "--out", str(results / "r.png")])
    assert not list(results.glob("*.json")), "a refused analysis writes no results"


def test_pooled_on_purpose_the_results_say_they_are_pooled(two_versions):
    data, results = two_versions
    assert _realism().main(["--data", str(data), "--results", str(results), "--out", str(results / "r.png"),
                            "--pool-protocols"]) == 0
    (payload,) = [json.loads(p.read_text()) for p in results.glob("realism.json")]
    assert payload["protocols_pooled"] is True
    assert sorted(payload["protocol_sha256"]) == ["a" * 64, "b" * 64]


def test_one_protocol_version_is_not_pooled(tmp_path):
    data = tmp_path / "data"
    write_dataset(data, {"realism": sim.simulate_realism(np.random.default_rng(3), n_subjects=4)}, simulated=True,
                  protocol_sha256={"realism": "a" * 64})
    assert _realism().main(["--data", str(data), "--results", str(tmp_path / "res"),
                            "--out", str(tmp_path / "r.png")]) == 0
    (payload,) = [json.loads(p.read_text()) for p in (tmp_path / "res").glob("realism.json")]
    assert payload["protocols_pooled"] is False


def test_make_figures_pool_1_pools_through_the_environment(two_versions, monkeypatch):
    """figures.mk exports PSYOP_POOL_PROTOCOLS=1 for POOL=1; the scripts take it as --pool-protocols."""
    data, results = two_versions
    monkeypatch.setenv("PSYOP_POOL_PROTOCOLS", "1")
    assert _realism().main(["--data", str(data), "--results", str(results), "--out", str(results / "r.png")]) == 0
    assert json.loads((results / "realism.json").read_text())["protocols_pooled"] is True
    mk = (ANALYSIS.parent / "figures.mk").read_text()
    assert "ifeq ($(POOL),1)\nexport PSYOP_POOL_PROTOCOLS := 1" in mk


A, B = "realism@aaaaaaaaaaaa", "realism@bbbbbbbbbbbb"


def test_make_rules_analyse_each_protocol_version_apart_from_its_own_sessions(two_versions):
    from psyop.cli.studies import make_rules

    data, _ = two_versions
    text, said = make_rules(data, ANALYSIS.parent / "protocols")
    assert f"--study {A} " in text and f"--study {B} " in text and "--study realism " not in text
    rule_a = next(line for line in text.splitlines() if line.startswith(f"$(FIGDIR)/{A}_preferences.png:"))
    rule_b = next(line for line in text.splitlines() if line.startswith(f"$(FIGDIR)/{B}_preferences.png:"))
    assert "sub-03" in rule_a and "sub-04" in rule_a and "sub-01" not in rule_a and "sub-02" not in rule_a
    assert "sub-01" in rule_b and "sub-02" in rule_b and "sub-03" not in rule_b
    assert any(line.startswith(f"{A} (pairwise preference; protocol version 1 of 2, 2 sessions, analysed apart")
               for line in said), said
    pooled, said = make_rules(data, ANALYSIS.parent / "protocols", pool_protocols=True)
    assert "--study realism " in pooled and "realism@" not in pooled
    assert said == ["realism (pairwise preference; 2 protocol versions pooled on purpose (POOL=1)): "
                    "realism_preferences.png, realism_gaze_quality.png"]


def test_each_version_gets_results_named_by_its_short_hash_and_the_summary_says_so(two_versions):
    data, results = two_versions
    for unit in (A, B):
        assert _realism().main(["--data", str(data), "--study", unit, "--results", str(results),
                                "--out", str(results / f"{unit}.png")]) == 0
    a, b = (json.loads((results / f"{unit}.json").read_text()) for unit in (A, B))
    assert (a["protocol_sha256"], b["protocol_sha256"]) == (["a" * 64], ["b" * 64])
    assert a["protocols_pooled"] is False and a["study_folder"] == "realism"
    assert a["study_protocol_versions"] == ["a" * 64, "b" * 64]
    assert a["summary"] != b["summary"], "each version is fitted on its own sessions"
    assert _script("results_table").main(["--results", str(results), "--protocols",
                                          str(ANALYSIS.parent / "protocols")]) == 0
    summary = (results / "summary.md").read_text()
    assert ("- study realism: its sessions ran 2 protocol versions, analysed apart as "
            f"{A}, {B} (one results set each; `make figures POOL=1` pools them)") in summary
    own = (results / f"{B}_summary.md").read_text()
    assert "**One protocol version (bbbbbbbbbbbb) of study realism**, analysed apart from its other version(s) " \
           "(aaaaaaaaaaaa)" in own


def test_make_figures_dry_run_builds_each_version(two_versions, tmp_path):
    """`make -n figures-build` (the graph `make figures` runs) lists one analysis per version, none refused."""
    data, results = two_versions
    env = dict(os.environ, PYTHONPATH=str(ANALYSIS.parent))
    env.pop("PSYOP_POOL_PROTOCOLS", None)
    run = subprocess.run(["make", "--no-print-directory", "-n", "-C", str(ANALYSIS.parent), "figures-build",
                          f"DATA={data}", f"RESULTS={results}", f"FIGDIR={tmp_path / 'figures'}"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    commands = [line for line in run.stdout.splitlines() if "analysis/fig_realism.py" in line]
    assert len(commands) == 2 and f"--study {A} " in commands[0] and f"--study {B} " in commands[1]
    assert f"{tmp_path / 'figures'}/{B}_preferences.png" in commands[1]
    assert "analysed apart" in run.stdout


def test_a_hash_that_names_no_version_is_refused_naming_the_versions(two_versions):
    data, results = two_versions
    with pytest.raises(UserError, match=r"no session of study 'realism' ran a protocol whose sha256 starts 'cccccc' "
                                        rf"\(its versions: {A}, {B}\)"):
        _realism().main(["--data", str(data), "--study", "realism@cccccc", "--results", str(results)])
    with pytest.raises(UserError, match="hex digits"):
        _realism().main(["--data", str(data), "--study", "realism@xyz", "--results", str(results)])


def test_a_session_without_a_hash_in_a_two_version_study_is_refused_not_dropped(two_versions):
    from psyop.cli.studies import make_rules

    data, _ = two_versions
    last = sorted(data.glob("realism/sub-*/ses-*/session.json"))[-1]
    meta = json.loads(last.read_text())
    del meta["protocol_sha256"]
    last.write_text(json.dumps(meta))
    with pytest.raises(UserError, match="records none .*POOL=1"):
        make_rules(data, ANALYSIS.parent / "protocols")

"""A model is loaded and prepared once per session (issue 26): ``psyop run`` and ``psyop simulate`` of
protocols/examples/teaser.yaml (two nodes of assets/teaser.glb) validate the protocol, record the models in
session.json and render the scene from one psyop.mesh.MeshFiles, so the file is parsed once for both its nodes
(psyop.mesh.load._parse, the one function that parses a model file, counted by a wrapper) and each (file, node)
selected from that parse once (psyop.mesh.load._select) although it is looked up by validation, by the
session.json records and by the scene."""

from __future__ import annotations

import collections
import json
from pathlib import Path

import pytest

import psyop.mesh.load as mesh_load
from psyop.cli import main as cli_main

TEASER = Path(__file__).resolve().parents[2] / "protocols" / "examples" / "teaser.yaml"
MODELS = {("teaser.glb", "bottle"), ("teaser.glb", "candle")}


@pytest.fixture
def counted(monkeypatch):
    """(selections, lookups) per (file name, node), and parses per file name, counted around the real functions."""
    selections: collections.Counter = collections.Counter()
    lookups: collections.Counter = collections.Counter()
    parses: collections.Counter = collections.Counter()
    real_select, real_parse, real_lookup = mesh_load._select, mesh_load._parse, mesh_load.MeshFiles.load

    def select(reader, node):
        selections[(Path(reader.path).name, node)] += 1
        return real_select(reader, node)

    def parse(path, raw):
        parses[Path(path).name] += 1
        return real_parse(path, raw)

    def lookup(self, path, node=None, **kwargs):
        lookups[(Path(path).name, node)] += 1
        return real_lookup(self, path, node, **kwargs)

    monkeypatch.setattr(mesh_load, "_select", select)
    monkeypatch.setattr(mesh_load, "_parse", parse)
    monkeypatch.setattr(mesh_load.MeshFiles, "load", lookup)
    yield selections, lookups
    # the two nodes of teaser.glb share one parse of the file (issue 26: not one parse per node)
    assert dict(parses) == {"teaser.glb": 1}


def _meta(data: Path, participant: str) -> dict:
    return json.loads((data / "teaser" / f"sub-{participant}" / "ses-1" / "session.json").read_text())


def test_run_parses_each_model_once(tmp_path, counted):
    parses, lookups = counted
    data = tmp_path / "data"
    assert cli_main(["run", str(TEASER), "--participant", "P1", "--data", str(data), "--render", "images",
                     "--no-progress"]) == 0
    meta = _meta(data, "P1")
    assert meta["rendering"].startswith("images"), meta["rendering"]
    assert {(m["file"], m["node"]) for m in meta["meshes"]} == MODELS
    assert dict(parses) == {key: 1 for key in MODELS}
    # looked up by validation, the session.json records and the scene: three uses, one parse
    assert all(lookups[key] >= 3 for key in MODELS), dict(lookups)


def test_simulate_in_one_process_parses_each_model_once(tmp_path, counted):
    parses, lookups = counted
    data = tmp_path / "data"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(TEASER), "--participants", "1",
                     "--jobs", "1"]) == 0
    meta = _meta(data, "S01")
    assert meta["rendering"].startswith("images"), meta["rendering"]
    assert {(m["file"], m["node"]) for m in meta["meshes"]} == MODELS
    assert dict(parses) == {key: 1 for key in MODELS}
    # plan_jobs' validation, the session's validation, its records and its scene
    assert all(lookups[key] >= 4 for key in MODELS), dict(lookups)


def test_audit_parses_each_model_once_not_per_frame(tmp_path, counted):
    parses, lookups = counted
    assert cli_main(["audit", str(TEASER), "--no-progress", "--scale", "0.05", "--gazes", "1"]) == 0
    assert dict(parses) == {key: 1 for key in MODELS}
    assert all(lookups[key] >= 2 for key in MODELS), dict(lookups)  # validation, then the audited frames

"""The session frame's CPU savings (issue 21) show the participant the same thing and log the same
frames: a SceneRenderer that builds each frame's scene once for both eyes and keeps the items that do
not move gives the same scenes, images and frame checks as the former path (the whole scene for each
eye, every frame) for every shipped protocol; sessions log the same tables; the simulated tracker
gives the same samples as its former code. Timing: benchmarks/bench_frame_cpu.py."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from benchmarks.bench_frame_cpu import PROTOCOLS, former_tracker, protocol_text
from benchmarks.former import FormerSceneRenderer
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session import scene_renderer
from psyop.session.gaze.plan import FixationPlan, circling_target
from psyop.session.gaze.simulated import SimulatedTracker, SimulatedTrackerConfig
from psyop.session.phases import mode_for
from psyop.session.plan import compile_plan
from psyop.run.runner import SessionOptions, run_session
from psyop.session.scene_renderer import WATCHED_CHECK_EVERY, SceneRenderer
from tests.session.session_helpers import fast_protocol

pytestmark = pytest.mark.cross_cpu  # cached against former scene path: scenes, images and tables equal

HEADS = (((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)),  # no tracking: the scene object passes through
         ((0.01, -0.02, 0.005), (0.9990482, 0.0, 0.0436194, 0.0)))  # a tracked head, 5 deg yaw


def _frames(plan):
    """(phase, time into it, fixation, head pose) for every phase of a trial, the response phase included:
    a moving target and gaze, then a still stretch (reuse), the head tracked in every other frame."""
    for phase in (*plan.phases, plan.response.phase):
        for k in range(7):
            still = k >= 4
            t = (3 if still else k) / 90.0
            fixation = (0.03 * math.sin(0.4 * (3 if still else k)), 0.02, -1.0)
            yield phase, t, fixation, HEADS[k % 2 if k < 4 else 0]


def _scene_key(scene):
    """A scene to compare: its mesh instances by their model's file hash and node (each renderer loads its
    own MeshAsset, whose vertex arrays do not compare with ==), everything else as it is."""
    meshes = tuple((m.asset.sha256, m.asset.node, dataclasses.replace(m, asset=None)) for m in scene.meshes)
    return dataclasses.replace(scene, meshes=()), meshes


@pytest.mark.parametrize("name,stereo", [(n, False) for n in PROTOCOLS] + [("detection", True), ("ordinal", True)])
def test_cached_scenes_give_the_same_scenes_images_and_checks(tmp_path: Path, name: str, stereo: bool) -> None:
    path = tmp_path / f"{name}.yaml"
    path.write_text(protocol_text(name, stereo))
    protocol = load_protocol(path)
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    rows = compile_schedule(protocol, 3).to_dict("records")[:2]  # two trials: the cache starts again
    from psyop.rendering.renderer import create_headless_context

    ctx = create_headless_context()
    renderers = {flag: (SceneRenderer if flag else FormerSceneRenderer)(plan, scale=0.12, ctx=ctx, owns_ctx=False,
                                                                        check_every=WATCHED_CHECK_EVERY)
                 for flag in (True, False)}
    for r in renderers.values():  # 8x8 samples at edges, not 32x32: the same for both, and affordable on llvmpipe
        r.settings = dataclasses.replace(r.settings, samples_per_axis=8)
    try:
        n_images = 0
        for row in rows:
            for phase, t, fixation, head in _frames(plan):
                mode = mode_for(phase, row)
                checks = {flag: r.render(row, phase, mode, t, fixation, head_pose=head) for flag, r in renderers.items()}
                assert checks[True] == checks[False], (row["trial"], phase.name, t)
                fast, former = renderers[True], renderers[False]
                if former._renderer is None:
                    assert fast._renderer is None
                    continue
                assert _scene_key(fast._renderer.scene) == _scene_key(former._renderer.scene)
                for eye in plan.rig.eyes:
                    if eye in former._renderer._eyes:
                        assert np.array_equal(fast._renderer.image(eye), former._renderer.image(eye)), \
                            (row["trial"], phase.name, t, eye)
                        n_images += 1
        a, b = renderers[True]._renderer.stats, renderers[False]._renderer.stats
        assert (a.frames_rendered, a.frames_skipped, a.invalid_cameras) == \
               (b.frames_rendered, b.frames_skipped, b.invalid_cameras)
        assert n_images > 0
    finally:
        for r in renderers.values():
            r.close()
        ctx.release()


def test_a_stereo_frame_builds_its_scene_once_for_both_eyes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from psyop import stimulus

    path = tmp_path / "detection.yaml"
    path.write_text(protocol_text("detection", True))
    protocol = load_protocol(path)
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    phase = next(p for p in plan.phases if p.show == "stimulus")
    built: list[tuple[str, ...] | None] = []
    real = stimulus.build_scene

    def counting(*args, **kwargs):
        built.append(kwargs.get("show"))
        return real(*args, **kwargs)

    monkeypatch.setattr(stimulus, "build_scene", counting)
    renderer = SceneRenderer(plan, scale=0.12)
    try:
        renderer.render(row, phase, "ocular", 0.0, (0.0, 0.0, -1.0))  # the phase's static parts are built here
        built.clear()
        for k in range(1, 6):
            renderer.render(row, phase, "ocular", k / 90.0, (0.0, 0.0, -1.0))
    finally:
        renderer.close()
    assert built == [("fixation",)] * 5  # one build per stereo frame, of the moving target only


def _session_tables(root: Path, protocol_path: Path, former: bool, monkeypatch: pytest.MonkeyPatch) -> dict[str, pd.DataFrame]:
    class Small(FormerSceneRenderer if former else SceneRenderer):  # both runs at 173x192 px (legible text needs it)
        def __init__(self, plan, **kwargs) -> None:  # (a watched session renders full size: minutes on llvmpipe)
            kwargs["scale"] = 0.12
            super().__init__(plan, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(scene_renderer, "SceneRenderer", Small)
        options = SessionOptions(participant="P1", seed=5, data_root=root, progress=False, fsync=False,
                                 every_frame=True, render="images", check_scale=0.12)
        outcome = run_session(load_protocol(protocol_path), compile_schedule, options)
    assert outcome.status == "complete", outcome.message
    session = next(root.glob("*/sub-P1/ses-1"))
    return {name: pd.read_parquet(session / f"{name}.parquet") for name in ("trials", "frames", "gaze")}


@pytest.mark.parametrize("study", ["detection", "egocentric"])
def test_sessions_log_the_same_tables_with_and_without_the_frame_caches(tmp_path: Path, study: str,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    path = fast_protocol(tmp_path, study, phase_s=0.05)
    text = path.read_text()
    # a few trials are enough to compare every phase's frames
    text = text.replace("levels: [1, 2, 3]", "levels: [1]", 1).replace("levels: [0.50, 0.58, 0.67, 0.75, 0.82, 0.90]",
                                                                       "levels: [0.50, 0.90]", 1)
    path.write_text(text)
    new = _session_tables(tmp_path / "new", path, False, monkeypatch)
    old = _session_tables(tmp_path / "old", path, True, monkeypatch)
    assert len(new["frames"]) > 0 and new["frames"]["image_checked"].any()
    for name in new:
        pd.testing.assert_frame_equal(new[name], old[name], check_exact=True)


def _sample_key(sample) -> str:
    return repr(sample)  # every field, floats to the last bit (NaN included)


def test_the_simulated_tracker_gives_its_former_samples_bit_for_bit() -> None:
    config = SimulatedTrackerConfig(blink_rate_hz=2.0, nan_burst_rate_hz=1.0, dropout_rate_hz=0.5)
    trackers = [SimulatedTracker(11, config), former_tracker(11, config)]
    plans = [FixationPlan("cross", 0.0), FixationPlan("pursuit", 1.0, target=circling_target(16.0, 90.0, 40.0), seed=2),
             FixationPlan("free", 3.0, radius_deg=10.0, seed=9), FixationPlan("cross", 5.5)]
    keys: list[list[str]] = [[], []]
    for i, tracker in enumerate(trackers):
        for step in range(700):
            now = step / 110.0  # not the 120 Hz tick: samples repeat and skip like a 90 Hz loop's
            for plan in plans:
                if plan.start_s <= now and plan not in tracker._plans:
                    tracker.set_plan(plan)
            keys[i].append(_sample_key(tracker.latest(now)))
        keys[i] += [_sample_key(r) for r in tracker.drain_raw()]
    assert keys[0] == keys[1]
    assert sum("valid=False" in k for k in keys[0]) > 0  # blinks and NaN bursts were in it

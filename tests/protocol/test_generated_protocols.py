"""Generated protocols, end to end (issue 9, item 5).

Property: a protocol from the whole language either validates, compiles into a session plan,
runs headless (simulated tracker and observer, virtual clock, camera-only frames), finalises,
loads with psyop.statistics.dataset.load_dataset and goes through the analysis function of its
response kind -- or validation refuses it with a UserError located at file:line:column. There is
no third outcome.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from generated_protocols import TEXTURE, protocols
from hypothesis import HealthCheck, event, given, settings

from psyop.errors import UserError
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.run.runner import SessionOptions, run_session
from psyop.statistics.dataset import load_dataset

N_EXAMPLES = int(__import__("os").environ.get("PSYOP_GENERATED_EXAMPLES", "200"))


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory):
    """A folder for the generated protocols and their data; in memory (/dev/shm) where there is
    one, since every session fsyncs its metadata a few times."""
    import tempfile

    import matplotlib.image as mpimg

    shm = Path("/dev/shm")
    root = Path(tempfile.mkdtemp(prefix="psyop-generated-", dir=shm)) if shm.is_dir() else tmp_path_factory.mktemp("generated")
    mpimg.imsave(root / TEXTURE, np.random.default_rng(0).uniform(size=(8, 8, 3)))
    yield root
    shutil.rmtree(root, ignore_errors=True)


def analyse(kind: str, trials: pd.DataFrame, protocol) -> pd.DataFrame | dict:
    """The analysis function of each response kind (the one the paper's analysis scripts use)."""
    if kind == "two_interval":
        from psyop.statistics.psychometric import FitOptions, fit_psychometric_table

        return fit_psychometric_table(trials, level_column=protocol.response.level_factor, group_columns=("participant",),
                                      options=FitOptions(n_bootstrap=10, estimate_eta=False))
    if kind == "left_right_nearer":
        from psyop.statistics.binomial import binomial_test

        answered = trials[trials["correct"].notna()]
        return binomial_test(int(answered["correct"].astype(bool).sum()), len(answered), 0.5)
    if kind == "pairwise_preference":
        from psyop.statistics.binomial import pairwise_preferences

        return pairwise_preferences(trials)
    if kind == "with_against":  # analysis/nc_calibration.py's fit
        from psyop.statistics.nulling import fit_nulling, nulling_blocks

        return {p: fit_nulling(nulling_blocks(g)) for p, g in trials.groupby("participant")}
    from psyop.statistics.regression import linear_fits_by

    return linear_fits_by(trials, "target_fraction", "reach_m", "rendering")


@settings(max_examples=N_EXAMPLES, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example])
@given(generated=protocols())
def test_a_generated_protocol_runs_end_to_end_or_is_refused_with_its_location(workdir: Path, generated) -> None:
    text, mistake = generated
    path = workdir / "generated.yaml"
    path.write_text(text)
    try:
        protocol = load_protocol(path)
    except UserError as error:
        event(f"refused ({mistake or 'no planted mistake'})")
        assert re.match(rf"^{re.escape(str(path))}:\d+:\d+$", error.location or ""), (error.location, str(error))
        return
    assert mistake is None, f"a protocol with mistake {mistake!r} validated:\n{text}"
    adaptive = [f.adaptive.procedure for f in protocol.design.factors.values() if f.adaptive is not None]
    event(f"ran: {protocol.response.kind}" + (f" (adaptive {adaptive[0]})" if adaptive else ""))
    plan = compile_plan(protocol)
    assert plan.response.kind.name == protocol.response.kind
    root = workdir / "data"
    shutil.rmtree(root, ignore_errors=True)
    options = SessionOptions(participant="G1", seed=1, data_root=root, progress=False, fsync=False, render="cameras")
    outcome = run_session(protocol, compile_schedule, options)
    assert outcome.status == "complete", outcome.message
    meta = json.loads((root / "generated" / "sub-G1" / "ses-1" / "session.json").read_text())
    assert meta["status"] == "complete" and meta["ipd_m"] == plan.rig.ipd_m
    dataset = load_dataset(root, "generated")
    not_run = (meta.get("adaptive_stop") or {}).get("n_trials_not_run", 0)  # left out by a target_sd stop
    if not_run:
        event("an adaptive stop left scheduled trials out")
    assert dataset.simulated and len(dataset.trials) == (len(compile_schedule(protocol, 1)) - protocol.design.practice_trials
                                                         - not_run)
    result = analyse(protocol.response.kind, dataset.trials, protocol)
    assert len(result) > 0


N_RENDERED = int(__import__("os").environ.get("PSYOP_GENERATED_RENDERED", "20"))


@pytest.fixture(scope="module")
def gl_context():
    from psyop.rendering.renderer import create_headless_context

    try:
        context = create_headless_context()
    except Exception as exc:  # noqa: BLE001 - no OpenGL here
        pytest.skip(f"no OpenGL context: {exc}")
    yield context
    context.release()


@settings(max_examples=N_RENDERED, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example,
                                 HealthCheck.function_scoped_fixture])
@given(generated=protocols())
def test_every_phase_of_a_generated_protocol_renders_for_a_watching_participant(workdir: Path, gl_context,
                                                                              generated) -> None:
    """What a watching participant sees: each phase of the first trial, each eye, drawn from the plan
    (small images; finite, and not empty where the phase shows a stimulus)."""
    from psyop.session.scene_renderer import SceneRenderer

    text, _ = generated
    path = workdir / "rendered.yaml"
    path.write_text(text)
    try:
        protocol = load_protocol(path)
    except UserError:
        return
    plan = compile_plan(protocol)
    row = compile_schedule(protocol, 1).iloc[-1].to_dict()
    if plan.adaptive is not None:  # the session places the adaptive level each trial: its first level here
        from psyop.adaptive.staircase import StaircaseSpec

        spec = plan.adaptive.spec
        row[plan.adaptive.factor] = float(spec.start if isinstance(spec, StaircaseSpec) else spec.stimulus[0])
    scale = min(1.0, max(0.25, 400 / plan.display.height_px))  # 400 px tall at least: room for legible text
    try:
        renderer = SceneRenderer(plan, scale=scale, ctx=gl_context, owns_ctx=False)
    except UserError as refused:  # text that cannot be drawn legibly even so is refused at start, in one line
        assert "px view" in refused.message and "\n" not in str(refused), refused
        event("refused at start: its text does not fit the display legibly")
        return
    try:
        for phase in (*plan.phases, plan.response.phase):
            check = renderer.render(row, phase, plan.mode_for(phase, row), 0.05, (0.0, 0.0, -1.0))
            assert check.ok or not check.checked, (phase, text)
            assert check.checked == phase.renders, phase
    finally:
        renderer.close()

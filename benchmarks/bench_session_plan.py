"""Cost of the session plan against the path it replaced (the protocol adapter + getattr reads).

Side by side in one run, for each of the five shipped protocols:
- compilation: ``compile_plan(protocol)`` against the old adapter (``phases_from_protocol``,
  ``resolve_display_profile``, ``resolve_eye_model``, the ipd/observer/fixation getattr reads),
  reproduced below as it was before the plan (commit 18105d0, psyop/session/protocol_adapter.py);
- per trial in the session loop: ``TrialLoop.run_trial`` over the schedule's trials (virtual clock,
  sampled frames, camera-only renderer, a simulated observer), driven by the plan's phases and
  response plan against the old adapter's phases.
The ratio plan / old is what to read; absolute times on this CPU are context only.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Any

from benchmarks.timing import median_s

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
STUDIES = ("detection", "discrimination", "ordinal", "egocentric", "realism")


# ---- the old path (before the session plan), kept here only to measure against -------------------------
def _legacy_compile(protocol: Any) -> tuple:
    from psyop.protocol import resolve_display_profile, resolve_eye_model
    from psyop.session.phases import PhaseSpec
    from psyop.protocol.kinds import KINDS

    columns_by_kind = {"two_interval": ("mode_interval1", "mode_interval2"), "left_right_nearer": ("mode",),
                       "pairwise_preference": ("mode_a", "mode_b"), "reach": ("rendering",)}
    kind = {  # noqa: F841 - the former code looked it up: its cost is measured
        "two_interval": KINDS["two_interval"], "left_right_nearer": KINDS["left_right_nearer"],  # (the former enum)
        "pairwise_preference": KINDS["pairwise_preference"], "reach": KINDS["reach"]}[protocol.response.kind]

    def duration(phase: Any) -> float:
        for name in ("duration_s", "min_duration_s", "expected_s"):
            value = getattr(phase, name, None)
            if value is not None:
                return float(value)
        return 0.0

    path = None
    for item in getattr(protocol, "scene", None) or []:
        if getattr(item, "kind", None) == "fixation_target" and getattr(item, "path", None) is not None:
            path = (float(getattr(item.path, "eccentricity_deg", 16.0)), float(getattr(item.path, "speed_deg_s", 90.0)))
            break
    gaze = "pursuit" if path is not None else "free"
    columns = columns_by_kind[protocol.response.kind]
    out, n_interval = [], 0
    for phase in getattr(getattr(protocol, "trial", None), "phases", None):
        k = getattr(phase, "kind", "")
        if k == "drift_recalibration":
            out.append(PhaseSpec("recalibration", duration(phase), "cross", "cross"))
        elif k == "interval":
            columns[min(n_interval, len(columns) - 1)]  # the old per-kind column lookup (its cost)
            n_interval += 1
            # the loop now reads modes by one rule (mode_interval<k>); both paths share it here
            out.append(PhaseSpec(f"interval{n_interval}", duration(phase), "stimulus", gaze,
                                 f"mode_interval{n_interval}", interval=n_interval))
        elif k == "blank":
            off = bool(getattr(phase, "display_off", False))
            out.append(PhaseSpec("display_off" if off else "blank", duration(phase), "off" if off else "blank",
                                 "none" if off else gaze))
        elif k == "response":
            break
    display = resolve_display_profile(protocol.display)
    eye = resolve_eye_model(protocol.display)
    ipd = getattr(protocol.display.ipd, "ipd_m", None) or 0.063
    observer = protocol.observer.model_dump() if protocol.observer is not None else None
    return tuple(out), display, eye, ipd, observer, path


# ---- measurements ----------------------------------------------------------------------------------------
class _NoStore:
    run_index = 0


def _per_trial_s(protocol: Any, rows: list[dict], phases: tuple, response: Any, rig: Any, display: Any,
                 observer: dict) -> float:
    from psyop.session.clock import VirtualClock
    from psyop.session.frames import CameraRenderer, HeadlessDisplay
    from psyop.session.gaze.simulated import SimulatedTracker
    from psyop.session.loop import LoopConfig, TrialLoop
    from psyop.session.responses.simulated import make_observer

    clock = VirtualClock()
    loop = TrialLoop(identity={"study": "bench", "participant": "B", "session": 1}, phases=phases, clock=clock,
                     gaze=SimulatedTracker(1), responses=make_observer(observer, seed=1, participant="B"),
                     renderer=CameraRenderer(display, rig), display=HeadlessDisplay(clock, 90.0), store=_NoStore(),
                     config=LoopConfig(progress=False, every_frame=False), response=response)
    start = time.perf_counter()
    for row in rows:
        loop.run_trial(row)
    return (time.perf_counter() - start) / len(rows)


def run(out_dir: Path, quick: bool) -> str:
    from psyop.optics.rig import EyeRig
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.plan import compile_plan

    repeats = 20 if quick else 200
    n_trials = 20 if quick else 100
    lines = [
        "## Session plan against the old protocol adapter (bench_session_plan)",
        "",
        f"Per protocol: compile (median of {repeats}) and per-trial loop cost ({n_trials} trials, best of 5 interleaved rounds; virtual clock,",
        "sampled frames, camera-only renderer, simulated observer), plan and old path side by side.",
        "",
        "| protocol | compile old | compile plan | ratio | per trial old | per trial plan | ratio |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    ratios = []
    for study in STUDIES:
        protocol = load_protocol(PROTOCOLS / f"{study}.yaml")
        t_old = median_s(lambda: _legacy_compile(protocol), repeats)
        t_plan = median_s(lambda: compile_plan(protocol), repeats)
        plan = compile_plan(protocol)
        phases_old, display, eye, ipd, observer, _ = _legacy_compile(protocol)
        rig_old = EyeRig(eye, ipd, ("left", "right"))  # the old camera renderer computed both eyes
        rows = compile_schedule(protocol, 1).head(n_trials).to_dict("records")
        # warm up both paths, then interleave them to share any drift of the machine's load
        _per_trial_s(protocol, rows[:2], phases_old, None, rig_old, display, observer)
        _per_trial_s(protocol, rows[:2], plan.phases, plan.response, plan.rig, plan.display, plan.observer_params())
        old_trial, plan_trial = [], []
        for _ in range(5):
            old_trial.append(_per_trial_s(protocol, rows, phases_old, None, rig_old, display, observer))
            plan_trial.append(_per_trial_s(protocol, rows, plan.phases, plan.response, plan.rig, plan.display,
                                           plan.observer_params()))
        p_old, p_plan = min(old_trial), min(plan_trial)  # least disturbed of 5 interleaved rounds
        ratios.append((t_plan / t_old, p_plan / p_old))
        lines.append(f"| {study} | {t_old * 1e3:.3f} ms | {t_plan * 1e3:.3f} ms | {t_plan / t_old:.2f} | "
                     f"{p_old * 1e3:.3f} ms | {p_plan * 1e3:.3f} ms | {p_plan / p_old:.2f} |")
    lines += [
        "",
        f"**Median ratio plan / old: compile {statistics.median(r[0] for r in ratios):.2f}, "
        f"per trial {statistics.median(r[1] for r in ratios):.2f}.** The plan compiles once per session; per",
        "trial it adds only the response-timeout check. Both paths here compute both eyes' cameras for the",
        "old path (as the old camera renderer did) and the protocol's eyes for the plan.",
    ]
    return "\n".join(lines)

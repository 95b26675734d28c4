"""The CPU side of a real session frame against the 90 Hz budget (issue 21), before and after, in one run.

What a frame is here: the loop's software path up to the GPU (``psyop.session.loop.TrialLoop._frame``
less the display and the log), on real frames of each shipped protocol's first interval of a trial
whose interval is rendered with ocular parallax where the protocol has one: the simulated tracker's
newest sample (``SimulatedTracker.latest``, following the phase's fixation plan: pursuit of the
circling target, or free viewing), the gaze conditioner, the simulated head pose (``--pose sim``, a
session's default; a headset tracks the head too) and its conditioner, so the world-fixed scene is
moved into head space every frame, and ``SceneRenderer.render`` for every eye
of the frame (scene build, head pose, upload, cameras, reuse decision, the OpenGL calls that queue
the draw, the GPU-reduced image check of each eye's first and every 8th image, as a watched session
runs it). The stimulus time advances 1/90 s per frame, so a moving fixation target really moves and
the scene really changes.

What is timed: ``time.thread_time()`` (CPU time of the calling thread) around that work, one frame
at a time. ``ctx.finish()`` after each frame is outside the timed region, and time the thread spends
blocked (waiting for the rasteriser on a readback) is not CPU time, so GL waits are excluded. Not
``time.process_time()``: that also counts llvmpipe's rasteriser threads, the work a GPU takes over.
The CPU path does not depend on the image size (the aperture mask, the one per-pixel CPU step, is
computed once per eye), so frames render at a reduced resolution; the full-resolution row checks
that claim.

Rows: each shipped protocol as it runs (one eye, or two for the stereo egocentric study), then each
monocular protocol rendered stereo (``eyes: stereo``: what a headset's stereo frame of that scene
costs), detection with more disc items (8, 64 and 128 primitives, stereo) for the cost per primitive,
and detection stereo with the head not tracked (the identity pose: the scene passes through).

Before: the former path, kept callable in benchmarks/former.py: ``FormerSceneRenderer`` (the whole scene
built for each eye, every frame, and moved into head space one primitive at a time:
``scene_in_head_per_primitive``) drawn by ``FormerRenderer`` (reuse bounds after every
draw, one primitive at a time; primitive table and uniforms rewritten every frame; the former screen
bounds), and a simulated
tracker that draws its per-plan error offset with a new numpy Generator per sample
(:func:`former_tracker`, the former code). After: the defaults. Before and after
run interleaved (alternating blocks of frames), on one OpenGL context; per row the medians of the
per-frame times and the ratio of the medians. Same images and frame checks before and after:
tests/session/test_frame_cpu_equality.py.
"""

from __future__ import annotations

import math
import re
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BUDGET_MS = 1000.0 / 90.0
PROTOCOLS = ("detection", "discrimination", "egocentric", "ordinal", "realism")


def former_tracker(seed: int, config: Any = None) -> Any:
    """The simulated tracker as it was before issue 21: a numpy Generator built for every sample's plan
    offset, and event windows (blinks, NaN bursts, dropouts) searched with numpy masks. Same samples
    (tests/session/test_frame_cpu_equality.py); the benchmark's "before" gaze source."""
    from psyop.session.gaze.keyed import keyed_rng as _rng
    from psyop.session.gaze.simulated import SimulatedTracker, _EventTimes

    class _FormerEventTimes(_EventTimes):
        def _starts(self, window: int) -> Any:
            starts = self._cache.get(window)
            if starts is None:
                if len(self._cache) > 64:
                    self._cache.clear()
                rng = _rng(self.seed, self.stream, window)
                starts = window + np.sort(rng.uniform(0, 1, rng.poisson(self.rate_hz)))
                self._cache[window] = starts
            return starts

        def start_containing(self, t_s: float) -> float | None:
            if self.rate_hz <= 0:
                return None
            for w in range(int(math.floor(t_s - self.duration_s)), int(math.floor(t_s)) + 1):
                starts = self._starts(w)
                hit = starts[(starts <= t_s) & (t_s < starts + self.duration_s)]
                if hit.size:
                    return float(hit[0])
            return None

    class _FormerTracker(SimulatedTracker):
        def __init__(self, seed: int, config: Any = None) -> None:
            super().__init__(seed, config)
            c = self.config
            self._dropouts = _FormerEventTimes(self.seed, 3, c.dropout_rate_hz, c.dropout_s)
            self._blinks = _FormerEventTimes(self.seed, 4, c.blink_rate_hz, c.blink_s)
            self._nan_bursts = _FormerEventTimes(self.seed, 5, c.nan_burst_rate_hz, c.nan_burst_s)

        def _plan_offset(self, plan: Any) -> np.ndarray:
            sigma = self.config.error_centre_deg / (math.sqrt(2.0) * math.sqrt(math.pi / 2.0))
            rng = _rng(self.seed, 8, int(round(plan.start_s * 1000.0)), plan.seed)
            return rng.normal(0.0, sigma, 2)

    return _FormerTracker(seed, config)


def _discs(count: int) -> str:
    """``count`` solid discs scattered over +-20 deg at 0.5 to 3 D: background items that do not move."""
    items = []
    for i in range(count):
        az, el = -20.0 + 40.0 * ((i * 7) % count) / count, -20.0 + 40.0 * ((i * 11) % count) / count
        items.append(f"  - id: extra{i}\n    kind: disc\n    size_deg: 1.5\n    depth: {{D: {0.5 + 2.5 * i / count:.3f}}}\n"
                     f"    centre_deg: [{az:.3f}, {el:.3f}]\n    surface: {{kind: solid, rgb: [0.2, 0.6, 0.9]}}\n")
    return "".join(items)


def protocol_text(name: str, stereo: bool, extra_discs: int = 0) -> str:
    """A shipped protocol's text, optionally rendered stereo (``eyes: stereo``) and with ``extra_discs``
    more disc items before the fixation target (detection)."""
    text = (REPO / "protocols" / f"{name}.yaml").read_text()
    # a model the protocol names relative to protocols/ (egocentric's room), found from wherever the text is written
    text = text.replace("file: ../assets/", f"file: {(REPO / 'assets').resolve()}/")
    if stereo:
        text, n = re.subn(r"(?m)^eyes:\s*\w+", "eyes: stereo", text)
        assert n == 1
    if extra_discs:
        text, n = re.subn(r"(?m)^  - id: fixation$", _discs(extra_discs) + "  - id: fixation", text)
        assert n == 1
    return text


@dataclass
class _Variant:
    name: str
    renderer: Any
    gaze: Any
    conditioner: Any
    pose: Any  # the head pose source (None: not tracked, the identity pose every frame)
    head_conditioner: Any
    k: int = 0


def _setup(protocol: Any, ctx: Any, scale: float, before: bool, seed: int,
           head_tracked: bool = True) -> tuple[_Variant, Any, Any, Any]:
    from psyop.schedule import compile_schedule
    from psyop.session.gaze.filter import GazeConditioner
    from psyop.session.gaze.simulated import SimulatedTracker
    from psyop.session.loop import LoopConfig, TrialLoop
    from psyop.session.phases import mode_for
    from psyop.session.plan import compile_plan
    from psyop.session.pose import PoseConditioner, SimulatedPose
    from psyop.session.scene_renderer import WATCHED_CHECK_EVERY, SceneRenderer

    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    schedule = compile_schedule(protocol, seed)
    phase = next(p for p in plan.phases if p.show == "stimulus")
    rows = [r for r in schedule.to_dict("records") if mode_for(phase, r) == "ocular"] or schedule.to_dict("records")
    row = rows[0]
    from benchmarks.former import FormerSceneRenderer

    renderer = (FormerSceneRenderer if before else SceneRenderer)(plan, scale=scale, ctx=ctx, owns_ctx=False,
                                                                  check_every=WATCHED_CHECK_EVERY)
    gaze = former_tracker(seed) if before else SimulatedTracker(seed)
    # the loop's own plan for the phase (pursuit of the circling target, free viewing)
    planner = TrialLoop.__new__(TrialLoop)
    planner.config, planner.gaze = LoopConfig(), gaze
    planner._set_plan(phase, row, 1.0)
    pose = SimulatedPose(seed) if head_tracked else None  # `--pose sim`, the default (a headset tracks too)
    variant = _Variant("before" if before else "after", renderer, gaze, GazeConditioner(), pose, PoseConditioner())
    return variant, row, phase, mode_for(phase, row)


def _frame(v: _Variant, row: Any, phase: Any, mode: str) -> float:
    """One frame's CPU ms (thread time), the GPU wait after it untimed."""
    t_in_phase = (v.k % max(1, int(phase.duration_s * 90))) / 90.0
    v.k += 1
    now_s = 1.0 + t_in_phase
    start = time.thread_time()
    gaze = v.conditioner.condition(v.gaze.latest(now_s))
    head = v.head_conditioner.condition(v.pose.head(now_s) if v.pose is not None else None)
    v.renderer.render(row, phase, mode, t_in_phase, gaze.fixation_m, head_pose=(head.position_m, head.orientation_wxyz))
    elapsed = time.thread_time() - start
    v.renderer._renderer.finish()
    return elapsed * 1e3


def measure(text: str, ctx: Any, scale: float, frames: int, block: int = 8, seed: int = 1,
            head_tracked: bool = True) -> dict[str, Any]:
    """Median CPU ms per frame before and after for one protocol text (see the module docstring)."""
    from psyop.protocol import load_protocol

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "study.yaml"
        path.write_text(text)
        protocol = load_protocol(path)
        variants = []
        try:
            for before in (True, False):
                v, row, phase, mode = _setup(protocol, ctx, scale, before, seed, head_tracked)
                variants.append(v)
            for v in variants:  # warm-up: programs, textures, the aperture mask, the first check
                for _ in range(4):
                    _frame(v, row, phase, mode)
            times: dict[str, list[float]] = {v.name: [] for v in variants}
            for rep in range(max(1, frames // block)):  # interleaved blocks, alternating which goes first
                for v in (variants if rep % 2 == 0 else variants[::-1]):
                    times[v.name] += [_frame(v, row, phase, mode) for _ in range(block)]
            eyes = len(variants[0].renderer.eyes)
            n_prims = len(variants[1].renderer._renderer.scene.primitives)
            size = f"{variants[0].renderer.display.width_px}x{variants[0].renderer.display.height_px}"
        finally:
            for v in variants:
                v.renderer.close()
    med = {k: statistics.median(x) for k, x in times.items()}
    return {"eyes": eyes, "prims": n_prims, "size": size, "mode": mode, "before_ms": med["before"],
            "after_ms": med["after"], "ratio": med["after"] / med["before"], "frames": len(times["after"])}


def _gaze_latest(n: int) -> tuple[float, float, bool]:
    """Median us per ``latest`` call, former and current tracker, interleaved; and whether every sample is
    identical."""
    from psyop.session.gaze.plan import FixationPlan, circling_target
    from psyop.session.gaze.simulated import SimulatedTracker

    trackers = {"before": former_tracker(7), "after": SimulatedTracker(7)}
    for tr in trackers.values():
        tr.set_plan(FixationPlan("pursuit", 0.5, 1.0, target=circling_target(16.0, 90.0, 30.0), seed=3))
    times: dict[str, list[float]] = {k: [] for k in trackers}
    samples: dict[str, list[Any]] = {k: [] for k in trackers}
    for rep in range(n):
        for name in (("before", "after") if rep % 2 == 0 else ("after", "before")):
            now = 0.6 + rep / 90.0
            start = time.thread_time()
            s = trackers[name].latest(now)
            times[name].append((time.thread_time() - start) * 1e6)
            samples[name].append(s)
    same = samples["before"] == samples["after"]
    return statistics.median(times["before"]), statistics.median(times["after"]), same


def _slope(rows: list[tuple[int, dict[str, Any]]], key: str) -> float:
    x = np.array([r["prims"] for _, r in rows], dtype=float)
    y = np.array([r[key] for _, r in rows], dtype=float)
    return float(np.polyfit(x, y, 1)[0])


def run(out_dir: Path, quick: bool) -> str:
    from psyop.rendering.renderer import create_headless_context

    scale = 0.12  # the smallest scale at which the shipped protocols' text is legible (psyop.session.text_fit)
    frames, block = (8, 4) if quick else (160, 8)
    ctx = create_headless_context()
    try:
        shipped = [(name, measure(protocol_text(name, False), ctx, scale, frames, block)) for name in PROTOCOLS]
        stereo = [(name, measure(protocol_text(name, True), ctx, scale, frames, block)) for name in PROTOCOLS
                  if name != "egocentric" and (not quick or name == "detection")]
        counts = (4, 60) if quick else (4, 60, 124)
        sized = [(c, measure(protocol_text("detection", True, c), ctx, scale, frames, block)) for c in counts]
        untracked = measure(protocol_text("detection", True), ctx, scale, frames, block, head_tracked=False)
        full = None if quick else measure(protocol_text("detection", True), ctx, 1.0, 24, block=4)
    finally:
        ctx.release()
    g_before, g_after, g_same = _gaze_latest(60 if quick else 600)

    def line(label: str, r: dict[str, Any]) -> str:
        return (f"| {label} | {r['eyes']} | {r['prims']} | {r['mode']} | {r['before_ms']:.2f} | "
                f"{100 * r['before_ms'] / BUDGET_MS:.0f} % | {r['after_ms']:.2f} | {100 * r['after_ms'] / BUDGET_MS:.0f} % | "
                f"{r['ratio']:.2f} |")

    size = shipped[0][1]["size"]
    lines = [
        "## CPU per frame against the 90 Hz budget (11.1 ms), before and after (issue 21)",
        "",
        f"CPU (thread) ms per frame outside GL waits: simulated gaze and head pose (`--pose sim`) + conditioning + "
        f"SceneRenderer.render of every eye, stimulus time advancing 1/90 s per frame (moving fixation target), "
        f"the head moving; {size} px per eye "
        f"(the CPU path should not depend on it: full-resolution row below); median over {shipped[0][1]['frames']} "
        f"frames each, before and after interleaved in blocks of {block}. Before: benchmarks/former.py's FormerSceneRenderer "
        "and FormerRenderer, the per-primitive head transform, the former simulated tracker; "
        "after: the defaults (benchmarks/bench_frame_cpu.py docstring). Full-resolution row: the same frames at the "
        "display's own size, to compare with the reduced size (the GPU work is not timed).",
        "",
        "| scene | eyes | primitives | mode | before ms | of budget | after ms | of budget | after / before |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [line(f"{name} (as shipped)", r) for name, r in shipped]
    lines += [line(f"{name} rendered stereo", r) for name, r in stereo]
    lines += [line(f"detection stereo + {c} discs", r) for c, r in sized]
    lines.append(line("detection stereo, head not tracked (identity pose)", untracked))
    if full is not None:
        lines.append(line(f"detection stereo at full resolution ({full['size']}, {full['frames']} frames)", full))
    slope_b, slope_a = _slope(sized, "before_ms"), _slope(sized, "after_ms")
    lines += [
        "",
        f"Cost per primitive per stereo frame (least-squares slope over {', '.join(str(r['prims']) for _, r in sized)} "
        f"primitives): before {1e3 * slope_b:.1f} us, after {1e3 * slope_a:.1f} us "
        f"(after / before {slope_a / slope_b:.2f}; goal <= 0.5).",
        "",
        f"Simulated tracker `latest`: before {g_before:.1f} us, after {g_after:.1f} us per call (median, "
        f"interleaved); samples identical: {g_same}.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    print(run(Path("bench"), quick=True))

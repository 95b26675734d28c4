"""The image observer (``observer: {kind: image}``): its calibration, its predictions beside the paper's, its
answer where the stimulus carries no cue, its resolution error and its cost per trial.

- Calibration: on the paper's detection stimulus (protocols/detection.yaml, back surface at 1, 2, 3 D, the
  fixation target's start and direction as the schedule draws them) the noise sd that puts the observer's mean
  p(correct) at 0.75 at 0.36 D (the paper's threshold; lapse 0). This is the default
  ``CALIBRATED_NOISE_SD_C2DEG2`` of psyop/protocol/image_observer.py.
- Detection, with that noise: p(correct) at the protocol's levels and the 75 % point per back distance
  (the paper: about 0.36 D, invariant to back distance).
- Control: the detection stimulus with both intervals conventional (identical frames): the responses' largest
  difference and p(correct).
- Discrimination (protocols/discrimination.yaml, nothing refitted): the 75 % point per offset beside the paper's
  line, 0.38 + 0.11 x offset (D).
- Resolution: the response difference at render_scale 0.25 (the default) over the same at 0.5.
- Ordinal (protocols/ordinal.yaml answered by the image observer's left/right-nearer rule,
  psyop/session/image_observer/ordinal.py; nothing refitted, its shift noise the stated default): p(correct) per
  rendering mode and separation beside the paper's (Sec. 6.1 Results, the values protocols/ordinal.yaml's
  ordinal_accuracy observer states), the evidence's sign agreement with the near side, the conventional trials'
  largest |evidence| (no cue: 0) and a binomial test of their simulated answers against 0.5, the evidence's
  agreement at render_scale 0.1 against the default 0.25 (the resolution's error), and CPU per trial.
- Cost: CPU seconds (this process, llvmpipe's threads included) per simulated trial at the defaults.

- Realism (protocols/realism.yaml answered by the image observer's preference rule,
  psyop/session/image_observer/preference.py; a stated hypothesis about preference, nothing refitted): p(first
  preferred) per comparison beside the paper's (Sec. 7 Results), the simulated answers' binomial test against 0.5,
  the identical-interval control (both intervals conventional: the same frames), the depth evidence of each mode's
  intervals beside a flat control (every target at one depth) and CPU per trial.

``python -m benchmarks --only image_observer --out bench`` writes bench/image_observer.md,
bench/image_observer_predictions.csv (detection, discrimination and realism rows), image_observer_ordinal.csv and
image_observer_realism.csv. ``python benchmarks/bench_image_observer.py OUT --realism-only`` runs the realism part
alone (OUT/image_observer_realism.md and .csv): the whole benchmark takes minutes on a shared 2-core machine.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import brentq
from scipy.stats import norm

REPO = Path(__file__).resolve().parents[1]
DETECTION = REPO / "protocols" / "detection.yaml"
DISCRIMINATION = REPO / "protocols" / "discrimination.yaml"
ORDINAL = REPO / "protocols" / "ordinal.yaml"
PAPER_DETECTION_D = 0.36  # analysis/paper_values.py: detection threshold (mean), "approximately 0.36 D"


def paper_discrimination_D(offset_D: float) -> float:
    """The paper's discrimination line (analysis/paper_values.py: intercept 0.38 D, slope 0.11)."""
    return 0.38 + 0.11 * offset_D


def observer_for(path: Path, text_edit: tuple[str, str] | None = None, **params: float):
    """An image observer for the protocol at ``path`` (its text edited by ``text_edit``, a replacement) and the
    schedule rows of one participant."""
    import tempfile

    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.plan import compile_plan
    from psyop.session.responses.image_observer import ImageObserverSource

    text = path.read_text()
    if text_edit is not None:
        assert text_edit[0] in text, text_edit
        text = text.replace(*text_edit)
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / path.name
        copy.write_text(text)
        protocol = load_protocol(copy)
        plan = compile_plan(protocol, tracker_ipd_m=0.064)
        rows = compile_schedule(protocol, 1).to_dict("records")
    source = ImageObserverSource({"kind": "image", **params}, seed=1, participant="B", plan=plan)
    return source, rows


def differences(source, rows: Iterable[dict]) -> np.ndarray:
    """R(correct interval) - R(other) for each row."""
    out = []
    for row in rows:
        r = source.responses(row)
        c = int(row["correct_interval"])
        out.append(r[c - 1] - r[2 - c])
    return np.asarray(out)


def pick(rows: list[dict], n: int, **levels: float) -> list[dict]:
    """The first ``n`` rows with the given factor levels (each a different trial: its own target path)."""
    chosen = [r for r in rows if all(abs(float(r[k]) - v) < 1e-9 for k, v in levels.items())]
    return chosen[:n]


def with_level(rows: list[dict], level_D: float) -> list[dict]:
    """The rows with their level set to ``level_D`` (the front surface's depth reads it)."""
    return [dict(r, level_D=level_D, trial_seed=int(r["trial_seed"]) + round(level_D * 1e6)) for r in rows]


def p_correct(delta: np.ndarray, noise_sd: float) -> float:
    return float(np.mean(norm.cdf(delta / (noise_sd * np.sqrt(2.0)))))


def threshold_D(levels: np.ndarray, p: np.ndarray) -> float:
    """The 75 % point by linear interpolation of p over level (NaN where p never crosses 0.75)."""
    above = np.flatnonzero(p >= 0.75)
    if above.size == 0 or above[0] == 0:
        return float("nan")
    i = above[0]
    return float(levels[i - 1] + (0.75 - p[i - 1]) * (levels[i] - levels[i - 1]) / (p[i] - p[i - 1]))


def threshold_note(levels: np.ndarray, p: np.ndarray) -> str:
    """Why a 75 % point is not an estimate: p never reaches 0.75 (censored above), or p at the first level above
    the lowest is already near 1 (the interpolated point is an upper bound, set by the level spacing)."""
    above = np.flatnonzero(p >= 0.75)
    if above.size == 0:
        return f"censored: p < 0.75 up to {levels[-1]:g} D"
    if above[0] == 1 and p[1] >= 0.95:
        return f"upper bound: p = {p[1]:.2f} already at {levels[1]:g} D"
    return ""


def calibrate(n: int) -> tuple[float, float]:
    """The noise sd that puts mean p(correct) at 0.75 at 0.36 D; and CPU seconds per trial."""
    source, rows = observer_for(DETECTION)
    trials = [r for back in (1.0, 2.0, 3.0) for r in with_level(pick(rows, n, back_D=back, level_D=0.25),
                                                                  PAPER_DETECTION_D)]
    start = time.process_time()
    delta = differences(source, trials)
    cpu_s = (time.process_time() - start) / len(trials)
    source.close()
    noise = brentq(lambda s: p_correct(delta, s) - 0.75, 1e-12, 1.0)
    return float(noise), cpu_s


def detection_table(noise: float, n: int) -> list[dict]:
    source, rows = observer_for(DETECTION, noise_sd_c2deg2=noise)
    levels = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    out = []
    for back in (1.0, 2.0, 3.0):
        p = np.array([p_correct(differences(source, pick(rows, n, back_D=back, level_D=lv)), noise) for lv in levels])
        out.append({"study": "detection", "condition": f"back_D={back:g}", "p_by_level": p,
                    "levels": levels, "threshold_D": threshold_D(levels, p), "note": threshold_note(levels, p),
                    "paper_D": PAPER_DETECTION_D})
    source.close()
    return out


def discrimination_table(noise: float, n: int) -> list[dict]:
    source, rows = observer_for(DISCRIMINATION, noise_sd_c2deg2=noise)
    out = []
    for offset in (1.0, 2.0, 3.0):
        levels = np.array(sorted({float(r["level_D"]) for r in rows if float(r["offset_D"]) == offset}))
        p = np.array([p_correct(differences(source, pick(rows, n, offset_D=offset, level_D=lv)), noise)
                      for lv in levels])
        out.append({"study": "discrimination", "condition": f"offset_D={offset:g}", "p_by_level": p, "levels": levels,
                    "threshold_D": threshold_D(levels, p), "note": threshold_note(levels, p),
                    "paper_D": paper_discrimination_D(offset)})
    source.close()
    return out


def control(noise: float, n: int) -> tuple[float, float]:
    """The identical-interval control: the largest |R1 - R2| and the mean p(correct)."""
    source, rows = observer_for(DETECTION, ("test: {mode: ocular}", "test: {mode: conventional}"),
                                noise_sd_c2deg2=noise)
    trials = [r for back in (1.0, 3.0) for r in pick(rows, n, back_D=back, level_D=1.0)]
    delta = differences(source, trials)
    source.close()
    return float(np.max(np.abs(delta))), p_correct(delta, noise)


def resolution_ratio(n: int) -> tuple[float, float]:
    """Mean response difference at render_scale 0.25 over 0.5 (detection, back 2 D, level 0.5 and 1 D)."""
    ratios = []
    for level in (0.5, 1.0):
        deltas = []
        for scale in (0.25, 0.5):
            source, rows = observer_for(DETECTION, render_scale=scale)
            deltas.append(float(np.mean(differences(source, pick(rows, n, back_D=2.0, level_D=level)))))
            source.close()
        ratios.append(deltas[0] / deltas[1])
    return ratios[0], ratios[1]


def ordinal_observer(modes: str, **params: float):
    """The image observer answering protocols/ordinal.yaml with its rendering modes ``modes``, and the schedule
    rows of one participant."""
    import tempfile

    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.plan import compile_plan
    from psyop.session.responses.image_observer import ImageOrdinalSource

    text = ORDINAL.read_text().replace("levels: [conventional, ocular, reversed]", f"levels: {modes}")
    text = text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n" + \
        "".join(f"  {k}: {v}\n" for k, v in params.items())
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "ordinal.yaml"
        copy.write_text(text)
        protocol = load_protocol(copy)
        plan = compile_plan(protocol, tracker_ipd_m=0.064)
        rows = compile_schedule(protocol, 1).to_dict("records")
    source = ImageOrdinalSource({"kind": "image", **params}, seed=1, participant="B", plan=plan)
    return source, rows


def paper_ordinal() -> dict[tuple[str, float], float]:
    """The paper's ordinal accuracies (Sec. 6.1 Results), as protocols/ordinal.yaml's observer states them."""
    from psyop.protocol import load_protocol

    observer = load_protocol(ORDINAL).observer
    return {(mode, float(sep)): float(p) for mode, by_sep in observer.p_correct.items()  # type: ignore[union-attr]
            for sep, p in by_sep.items()}


def ordinal_table(n: int) -> tuple[list[dict], dict]:
    """Per mode and separation: p(correct), the evidence's sign agreement with the near side; and the
    conventional control's largest |evidence|, its simulated answers' binomial p and CPU per ocular trial."""
    from scipy.stats import binomtest

    from psyop.session.image_observer.ordinal import p_left

    source, rows = ordinal_observer("[conventional, ocular, reversed]")
    noise, paper, out = float(source.model.shift_noise_arcmin), paper_ordinal(), []
    cpu_s, largest, answers = [], 0.0, []
    for mode in ("conventional", "ocular", "reversed"):
        for sep in (1.0, 2.0):
            trials = pick_words(rows, n, mode=mode, separation_D=sep)
            p, agree = [], []
            for row in trials:
                start = time.process_time()
                evidence = source.evidence_arcmin(row)
                cpu_s.append(time.process_time() - start) if mode == "ocular" else None
                left = p_left(evidence, noise, 0.0)
                near_left = row["near_side"] == "left"
                p.append(left if near_left else 1.0 - left)
                if sum(evidence) != 0.0:  # no evidence: no sign to agree
                    agree.append(float(np.sign(sum(evidence)) * (1 if near_left else -1)))
                if mode == "conventional":
                    largest = max(largest, max(abs(e) for e in evidence))
                    answers.append(bool(source.collect(row, 0.0).correct))
            out.append({"study": "ordinal", "condition": f"{mode}, separation_D={sep:g}", "p": float(np.mean(p)),
                        "agree": float(np.mean(np.array(agree) > 0)) if agree else float("nan"), "paper": paper[(mode, sep)], "n": len(trials)})
    source.close()
    control = {"largest": largest, "binom_p": binomtest(sum(answers), len(answers), 0.5).pvalue,
               "correct": sum(answers), "n": len(answers), "cpu_s": float(np.mean(cpu_s))}
    return out, control


def pick_words(rows: list[dict], n: int, **levels: float | str) -> list[dict]:
    """The first ``n`` rows with the given factor levels (words compared as text, numbers to 1e-9)."""
    def same(a: object, b: float | str) -> bool:
        return str(a) == b if isinstance(b, str) else abs(float(a) - b) < 1e-9  # type: ignore[arg-type]

    return [r for r in rows if all(same(r[k], v) for k, v in levels.items())][:n]


def ordinal_resolution(n: int) -> float:
    """The share of ocular trials (separation 2 D) whose evidence says the near side at render_scale 0.1."""
    source, rows = ordinal_observer("[ocular]", render_scale=0.1)
    trials = pick_words(rows, n, separation_D=2.0)
    agree = [sum(source.evidence_arcmin(r)) * (1 if r["near_side"] == "left" else -1) > 0 for r in trials]
    source.close()
    return float(np.mean(agree))


def ordinal_lines(rows: list[dict], control: dict, low_res_agree: float) -> list[str]:
    """The ordinal section of the report."""
    lines = ["", "### Ordinal (left_right_nearer): the image observer's predictions beside the paper's", "",
             "Observer: image (left/right-nearer rule: the side whose shift against each gaze shift says nearer; "
             "shift_noise_arcmin 1.0 stated, nothing refitted; render_scale 0.25, 8 free-viewing fixations).", "",
             "| condition | trials | evidence says the near side | observer p(correct) | note | paper p(correct) |",
             "|---|---|---|---|---|---|"]
    def agreement(share: float) -> str:
        return "none (evidence 0)" if np.isnan(share) else f"{share:.2f}"

    def note(p: float) -> str:
        return "saturated: the evidence is many times the stated noise" if min(p, 1.0 - p) < 1e-3 else ""

    lines += [f"| {r['condition']} | {r['n']} | {agreement(r['agree'])} | {r['p']:.3f} | {note(r['p'])} | "
              f"{r['paper']:.3f} |" for r in rows]
    lines += ["", f"Conventional (no cue): largest |evidence| = {control['largest']:.3g} arcmin; simulated answers "
                  f"{control['correct']}/{control['n']} correct, binomial p = {control['binom_p']:.3f} against 0.5.",
              "", f"CPU per ocular trial (evidence of 7 frame pairs, rendering included): {control['cpu_s']:.2f} s.",
              "", f"Resolution: at render_scale 0.1 the evidence says the near side in {low_res_agree:.2f} of ocular "
                  "trials at 2 D (the textures' aliasing), against the table's 0.25.", ""]
    return lines


REALISM = REPO / "protocols" / "realism.yaml"
#: the paper's preferences (Sec. 7 Results; analysis/paper_values.py): (first, second) -> share of trials the
#: first was preferred
PAPER_PREFERENCES = {("ocular", "conventional"): 0.768, ("reversed", "conventional"): 0.751,
                     ("ocular", "reversed"): 0.491}
#: the realism scene's target depths (protocols/realism.yaml) and the flat control's (every target at 2 D: the
#: loader needs near > far, so 0.01 D apart)
REALISM_DEPTHS = ("near: {D: 3.5}", "far: {D: 0.5}")
FLAT_DEPTHS = ("near: {D: 2.01}", "far: {D: 2.0}")


def realism_text(flat: bool, grid: bool) -> str:
    """protocols/realism.yaml, its targets all at one depth where ``flat``, its grid planes left out unless
    ``grid``."""
    text = REALISM.read_text()
    if flat:
        for old, new in zip(REALISM_DEPTHS, FLAT_DEPTHS):
            assert old in text, old
            text = text.replace(old, new)
    if not grid:
        text = text[:text.index("  - id: grid")] + text[text.index("  - id: targets"):]
        assert "      show: [grid]" in text
        text = text.replace("      show: [grid]", "      show: []")
    return text


def realism_observer(flat: bool = False, grid: bool = True, **params: float):
    """The image observer answering protocols/realism.yaml (:func:`realism_text`), and the schedule rows of one
    participant."""
    import tempfile

    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.plan import compile_plan
    from psyop.session.responses.image_choices import ImagePreferenceSource

    text = realism_text(flat, grid)
    text = text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n" + \
        "".join(f"  {k}: {v}\n" for k, v in params.items())
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "realism.yaml"
        copy.write_text(text)
        protocol = load_protocol(copy)
        plan = compile_plan(protocol, tracker_ipd_m=0.064)
        rows = compile_schedule(protocol, 1).to_dict("records")
    source = ImagePreferenceSource({"kind": "image", **params}, seed=1, participant="B", plan=plan)
    return source, rows


def preferred_share(source, trials: list[dict], first: str) -> tuple[float, int, list[float]]:
    """Mean p(``first`` preferred), the simulated answers choosing it, and the evidence of the ``first`` mode's
    intervals (arcmin) over ``trials``."""
    p, chosen, evidence = [], 0, []
    for row in trials:
        _, p_a = source.decision(row)
        a_first = row["mode_a"] == first
        p.append(p_a if a_first else 1.0 - p_a)
        chosen += source.collect(row, 0.0).chosen_mode == first
        evidence.append(source.evidence_arcmin(row)[0 if a_first else 1])
    return float(np.mean(p)), chosen, evidence


def realism_table(n: int) -> tuple[list[dict], dict]:
    """Per paper comparison: the observer's p(first preferred), its simulated answers and binomial p against 0.5,
    beside the paper's share; and the controls: identical intervals (both conventional), the flat scene, CPU."""
    from scipy.stats import binomtest

    source, rows = realism_observer()
    out, cpu_s, evidence = [], [], {}
    for (first, second), paper in PAPER_PREFERENCES.items():
        trials = [r for r in rows if {r["mode_a"], r["mode_b"]} == {first, second}][:n]
        start = time.process_time()
        p, chosen, own = preferred_share(source, trials, first)
        cpu_s.append((time.process_time() - start) / len(trials))
        evidence.setdefault(first, []).extend(own)
        out.append({"study": "realism", "condition": f"{first} over {second}", "p": p, "chosen": chosen,
                    "n": len(trials), "binom_p": binomtest(chosen, len(trials), 0.5).pvalue, "paper_p": paper})
    same = [dict(r, mode_a="conventional", mode_b="conventional", mode_interval1="conventional",
                 mode_interval2="conventional") for r in rows[:2 * n]]
    gaps = [abs(a - b) for a, b in (source.evidence_arcmin(r) for r in same)]
    answers = [source.collect(r, 0.0).response == "a" for r in same]
    source.close()
    control = {"largest_gap": max(gaps), "first": sum(answers), "n_same": len(same),
               "binom_p": binomtest(sum(answers), len(same), 0.5).pvalue, "cpu_s": float(np.mean(cpu_s)),
               "ocular": evidence["ocular"], "reversed": evidence["reversed"], "flat": ocular_evidence(n, True, True),
               "targets": ocular_evidence(n, False, False), "flat_targets": ocular_evidence(n, True, False)}
    return out, control


def ocular_evidence(n: int, flat: bool, grid: bool) -> list[float]:
    """The depth evidence (arcmin) of the ocular intervals of the first ``n`` trials that show one, in the scene of
    :func:`realism_text`."""
    source, rows = realism_observer(flat=flat, grid=grid)
    out = [source.evidence_arcmin(r)[0 if r["mode_a"] == "ocular" else 1]
           for r in [r for r in rows if "ocular" in (r["mode_a"], r["mode_b"])][:n]]
    source.close()
    return out


def realism_lines(rows: list[dict], control: dict) -> list[str]:
    """The realism section of the report."""
    def spread(values: list[float]) -> str:
        return f"median {np.median(values):.2f}, range {min(values):.2f} to {max(values):.2f} (n = {len(values)})"

    lines = ["", "### Realism (pairwise_preference): the image observer's predictions beside the paper's", "",
             "Observer: image (preference rule, psyop/session/image_observer/preference.py: the interval whose frames "
             "carry more depth evidence from the eye's own movements is preferred; a stated hypothesis about "
             "preference, not a fit; shift_noise_arcmin 1.0 stated, nothing refitted; render_scale 0.25, "
             "8 free-viewing fixations per interval).", "",
             "| comparison | trials | observer p(first preferred) | simulated answers choosing the first "
             "(binomial p vs 0.5) | paper |", "|---|---|---|---|---|"]
    lines += [f"| {r['condition']} | {r['n']} | {r['p']:.3f} | {r['chosen']}/{r['n']} ({r['binom_p']:.3g}) | "
              f"{100 * r['paper_p']:.1f} % |" for r in rows]
    lines += ["", f"Identical intervals (both conventional, {control['n_same']} trials): largest |E_a - E_b| = "
                  f"{control['largest_gap']:.3g} arcmin; the first chosen {control['first']}/{control['n_same']}, "
                  f"binomial p = {control['binom_p']:.3f} against 0.5.", "",
              f"Depth evidence of the ocular intervals (arcmin): {spread(control['ocular'])}; of the reversed "
              f"intervals: {spread(control['reversed'])}; conventional intervals: 0 (the same frames at every "
              "fixation).", "",
              "Controls, ocular intervals (arcmin): every target at 2 D, the grid planes as in the study: "
              f"{spread(control['flat'])}; the targets alone (no grid planes), at the study's depths: "
              f"{spread(control['targets'])}; the targets alone, every one at 2 D: {spread(control['flat_targets'])}. "
              "Where a control without the targets' relative depth is as large as the scene with it, the evidence at "
              "this resolution does not come from the targets' relative depth (but from the grid planes' own depth "
              "or from the sampled textures), and the predictions say only that gaze-contingent rendering changes "
              "the frames with the gaze.", "",
              f"CPU per preference trial (two intervals, 7 frame pairs each, rendering included): "
              f"{control['cpu_s']:.2f} s.", ""]
    return lines


def realism_section(out_dir: Path, n: int) -> tuple[list[str], list[dict]]:
    """The realism part: its report lines and its prediction rows (also written to image_observer_realism.csv)."""
    rows, control = realism_table(n)
    pd.DataFrame([{"observer": "image", **r} for r in rows]).to_csv(out_dir / "image_observer_realism.csv",
                                                                   index=False)
    return realism_lines(rows, control), rows


def run(out_dir: Path, quick: bool = False) -> str:
    n = 1 if quick else 3
    noise, cpu_s = calibrate(n)
    rows = detection_table(noise, n) + discrimination_table(noise, n)
    largest, p_control = control(noise, n)
    ratio_half, ratio_one = resolution_ratio(1)
    realism, realism_rows = realism_section(out_dir, 2 if quick else 6)
    table = pd.DataFrame([{"observer": "image", **{k: (v if not isinstance(v, np.ndarray) else
                                                        " ".join(f"{x:.3g}" for x in v)) for k, v in r.items()}}
                          for r in rows + realism_rows])
    mean_detection_D = float(np.mean([r["threshold_D"] for r in rows if r["study"] == "detection"]))
    table.to_csv(out_dir / "image_observer_predictions.csv", index=False)
    lines = ["## Image observer (observer: {kind: image}): calibration and predictions", "",
             f"Observer: image (psyop/protocol/image_observer.py defaults; {n} trial(s) per cell, schedule seed 1).", "",
             f"Calibrated noise_sd_c2deg2 = **{noise:.4g}** (mean p(correct) 0.75 at {PAPER_DETECTION_D} D over back "
             f"1, 2, 3 D, {n} trial(s) each).", "",
             f"CPU per simulated trial (defaults: render_scale 0.25, 8 frames per interval): **{cpu_s:.2f} s**.", "",
             "| study | condition | levels (D) | p(correct) | observer 75 % point (D) | note | paper (D) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['study']} | {r['condition']} | {' '.join(f'{x:g}' for x in r['levels'])} | "
                     f"{' '.join(f'{x:.2f}' for x in r['p_by_level'])} | {r['threshold_D']:.3f} | {r['note']} | "
                     f"{r['paper_D']:.2f} |")
    lines += ["", f"Detection, the observer's 75 % point averaged over back 1, 2, 3 D: **{mean_detection_D:.3f} D** "
                  f"(paper: about {PAPER_DETECTION_D} D). Discrimination: nothing refitted.", "",
              f"Identical-interval control (both conventional, level 1 D): largest |R1 - R2| = {largest:.3g}, "
                  f"p(correct) = {p_control:.3f}.", "",
              f"Resolution: response difference at render_scale 0.25 / 0.5 = {ratio_half:.3f} (level 0.5 D), "
              f"{ratio_one:.3f} (level 1 D) (detection, back 2 D, 1 trial).", ""]
    ordinal_rows, ordinal_control = ordinal_table(2 if quick else 6)
    lines += ordinal_lines(ordinal_rows, ordinal_control, ordinal_resolution(2 if quick else 6))
    lines += realism
    pd.DataFrame([{"observer": "image", **r} for r in ordinal_rows]).to_csv(
        out_dir / "image_observer_ordinal.csv", index=False)
    section = "\n".join(lines) + "\n"
    (out_dir / "image_observer.md").write_text(section)
    return section


def run_realism(out_dir: Path, quick: bool = False) -> str:
    """The realism part alone (``--realism-only``): bench/image_observer_realism.md and .csv."""
    lines, _ = realism_section(out_dir, 2 if quick else 6)
    section = "\n".join(["## Image observer (observer: {kind: image}): realism only", *lines]) + "\n"
    (out_dir / "image_observer_realism.md").write_text(section)
    return section


if __name__ == "__main__":
    import sys

    arguments = [a for a in sys.argv[1:] if not a.startswith("--")]
    folder = Path(arguments[0]) if arguments else Path("bench")
    folder.mkdir(parents=True, exist_ok=True)
    part = run_realism if "--realism-only" in sys.argv else run
    print(part(folder, quick="--quick" in sys.argv))

"""results/summary.md in the paper's form, beside the paper: every statistic the paper reports with
the paper's value, psyop's value and whether the conclusion agrees (analysis/paper_values.py);
then each paper study's full statistics. Also results/summary.json.

The paper's rows come only from results whose sessions ran the paper's protocols, identified by the
protocol hash each results JSON records (analysis/_common.provenance) against the shipped files
protocols/<name>.yaml (analysis/paper_values.PAPER_PROTOCOLS), never by study name. Every other
study's results go to results/<study>_summary.md: a user's study never changes a paper row.
    python analysis/results_table.py --results results --out results/summary.md
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from _common import parser, run, write_json, write_text
from paper_values import CRITERION, PAPER_PROTOCOLS, paper_hashes, rows_for

from psyop.errors import UserError

#: The paper, cited by its reference (never by a path on the machine that built the summary).
PAPER_REFERENCE = ("Konrad, Angelopoulos and Wetzstein, \"Gaze-Contingent Ocular Parallax Rendering for Virtual "
                   "Reality\", ACM Transactions on Graphics, 2020 (sec. 5-6 and supplement)")


def study_results(results: Path) -> list[tuple[Path, dict]]:
    """Every results JSON an analysis script wrote (it has an ``analysis`` key), by file name."""
    found = []
    for path in sorted(results.glob("*.json")):
        if path.name.startswith("summary") or path.name.endswith("_summary.json"):
            continue
        try:
            payload = json.loads(path.read_text())
        except ValueError as exc:
            raise UserError(f"not valid JSON ({exc}); rerun the analysis script that wrote it", str(path)) from exc
        if isinstance(payload, dict) and "analysis" in payload and "study" in payload:
            found.append((path, payload))
    return found


def failed_studies() -> list[str]:
    """The studies whose analysis failed earlier in this run (analysis/batch.py sets
    ``PSYOP_FAILED_STUDIES``): their results here are from an earlier run, so they are not read."""
    return [s for s in os.environ.get("PSYOP_FAILED_STUDIES", "").split(",") if s]


def failed_lines(failed: list[str], results: Path) -> list[str]:
    """The summary's section naming the studies not analysed in this run; each one's
    results/<study>_summary.md says so too (no statistics from an earlier run stay beside it)."""
    if not failed:
        return []
    for study in failed:
        write_text(results / f"{study}_summary.md", f"# Statistics of study {study}\n\n**Not analysed**: its analysis "
                   "failed in the last `make figures` (its error is in that run's output); no statistics.\n")
    return ["## Studies not analysed", "",
            *(f"- {s}: its analysis failed in this run (the error is above in the run's output); its results "
              "are left out of this summary" for s in failed), ""]


def split_paper(found: list[tuple[Path, dict]], hashes: dict[str, str]) -> tuple[dict[str, dict], list[tuple[Path, dict]]]:
    """(paper key -> payload of the paper's protocol, every other results payload)."""
    paper: dict[str, dict] = {}
    others = []
    for path, payload in found:
        key = next((k for k, (_, analysis) in PAPER_PROTOCOLS.items()
                    if payload["analysis"] == analysis and payload.get("protocol_sha256") == [hashes[k]]), None)
        if key is None:
            others.append((path, payload))
        elif key in paper:
            raise UserError(f"two results of the paper's {PAPER_PROTOCOLS[key][0]} ({paper[key]['study']!r} and "
                            f"{payload['study']!r}); remove one", str(path))
        else:
            paper[key] = payload
    return paper, others


def _statistics(payload: dict, name: str) -> list[str]:
    lines = [f"### {payload.get('study', name)} (n = {payload.get('n_subjects', '?')})", ""]
    lines += [f"- {k}: {v}" for k, v in payload.get("summary", {}).items()]
    for key in ("left_out", "dropped"):
        if payload.get(key):
            lines.append(f"- {key}: " + "; ".join(json.dumps(x, sort_keys=True) for x in payload[key]))
    lines.append("")
    return lines


def display_lines(data: Path, studies: list[str]) -> list[str]:
    """A section saying, per study, whether its sessions ran on a calibrated display (session.json
    ``display_output``; docs/calibration.md): an uncalibrated session's stimuli are pixel values, so the luminances and
    contrasts on its screen are unknown. Empty when no study has sessions under ``data``."""
    from psyop.session.log.record import read_record_file
    from psyop.statistics.dataset import session_files

    lines = []
    for study in studies:
        try:
            outputs = [getattr(read_record_file(f.parent / "session.json"), "display_output", None)
                       for f in session_files(data, study)]
        except (UserError, OSError) as error:  # an unreadable session.json: said, not skipped
            lines.append(f"- {study}: display not known ({getattr(error, 'message', None) or error})")
            continue
        calibrated = sum(1 for o in outputs if o is not None and o.calibrated)
        unknown = sum(1 for o in outputs if o is None)
        if not outputs:
            continue
        parts = [f"uncalibrated in {len(outputs) - calibrated - unknown}"] if len(outputs) - calibrated - unknown else []
        parts += [f"not recorded in {unknown} (sessions before psyop recorded it)"] if unknown else []
        text = "calibrated display" if calibrated == len(outputs) else (
            "**uncalibrated display** (stimuli in pixel values: luminances and contrasts on the screen unknown): "
            f"{', '.join(parts)} of {len(outputs)} sessions")
        lines.append(f"- {study}: {text}")
    return ["## Display", "", *lines, ""] if lines else []


def write_study_summaries(others: list[tuple[Path, dict]], results: Path, data: Path | None = None) -> list[Path]:
    """results/<study>_summary.md for each study that is not one of the paper's protocols."""
    by_study: dict[str, list[dict]] = {}
    for _, payload in others:
        by_study.setdefault(payload["study"], []).append(payload)
    written = []
    for study, payloads in sorted(by_study.items()):
        hashes = sorted({h for p in payloads for h in p.get("protocol_sha256", [])})
        lines = [f"# Statistics of study {study}", "",
                 f"Protocol hash(es): {', '.join(h[:12] for h in hashes) or 'not recorded'} (not one of the paper's "
                 "protocols: these numbers are not compared with the paper).", ""]
        if len(hashes) > 1:
            lines += [f"**{len(hashes)} protocol versions pooled on purpose** (--pool-protocols / POOL=1).", ""]
        versions = payloads[0].get("study_protocol_versions") or []
        if len(hashes) == 1 and len(versions) > 1:
            others = ", ".join(h[:12] for h in versions if h != hashes[0])
            lines += [f"**One protocol version ({hashes[0][:12]}) of study {payloads[0].get('study_folder', study)}**, "
                      f"analysed apart from its other version(s) ({others}); `make figures POOL=1` pools them.", ""]
        if any(p.get("simulated") for p in payloads):
            lines += ["**Simulated data**.", ""]
        for payload in payloads:
            lines += [f"## {payload['analysis']}", ""] + _statistics(payload, study)[2:]
        lines += quality_lines(results, [study])
        lines += display_lines(data, [study]) if data is not None else []
        path = results / f"{study}_summary.md"
        write_text(path, "\n".join(lines) + "\n")
        written.append(path)
    return written


def versions_lines(payloads: list[dict]) -> list[str]:
    """What was done with studies whose sessions ran several protocol versions: each version analysed
    apart (``<study>@<hash12>``, the default) or pooled on purpose; [] when every study ran one."""
    apart: dict[str, set[str]] = {}
    pooled = set()
    for p in payloads:
        versions = p.get("study_protocol_versions") or []
        if len(p.get("protocol_sha256", [])) > 1:
            pooled.add(f"{p['study']} ({len(p['protocol_sha256'])} versions: "
                       f"{', '.join(h[:12] for h in p['protocol_sha256'])})")
        elif len(versions) > 1:
            apart.setdefault(str(p.get("study_folder", p["study"])), set()).add(str(p["study"]))
    lines = [f"- study {folder}: its sessions ran {len(units)} protocol versions, analysed apart as "
             f"{', '.join(sorted(units))} (one results set each; `make figures POOL=1` pools them)"
             for folder, units in sorted(apart.items())]
    lines += [f"- study {name}: protocol versions pooled on purpose (--pool-protocols / POOL=1)" for name in sorted(pooled)]
    return ["## Protocol versions", "", *lines, ""] if lines else []


def quality_lines(results: Path, studies: list[str]) -> list[str]:
    """The gaze-based exclusions of each study (results/<study>_quality.txt, analysis/gaze_quality.py)."""
    found = [(s, results / f"{s}_quality.txt") for s in studies]
    lines = [f"- {s}: {path.read_text().strip()}" for s, path in found if path.is_file()]
    return ["## Gaze-based exclusions (quality: rules; every analysis above ran on the included data)", "", *lines, ""] \
        if lines else []


def _open_intervals(report: dict | None) -> str:
    """' k of n fits used as numbers have an open or out-of-range 95 % CI (...): kept ...' or ''."""
    if not report:
        return ""
    counts = ", ".join(f"{k}: {v}" for k, v in report["by_flag"].items() if v) or "none"
    return (f" {report['n_open_or_out_of_range']} of {report['n_used']} fits used as numbers have an open or "
            f"out-of-range 95 % CI ({counts}): kept at their threshold, their per-fit intervals not used.")

def _methods(studies: dict) -> list[str]:
    lines = ["## How psyop computed these", ""]
    lines.append("- Psychometric fits (detection, discrimination): psignifit 4.3 priors and grid, 2AFC cumulative "
                 "normal on linear D; threshold = 75 %-correct point of the MAP curve. **Eta (overdispersion) is "
                 "fixed at 0** for the threshold and its CI (psignifit's default integrates over eta; with it the "
                 "95 % intervals covered the truth in 100 % of simulated observers). Eta is still estimated per fit "
                 "(the `eta` column of results/*_fits.csv) and overdispersion is tested by the deviance bootstrap.")
    for name in ("detection_thresholds", "discrimination_fit"):
        s = studies.get(name)
        if s is not None:
            left = s.get("left_out_by_status") or {}
            lines.append(f"- {s['study']}: {s.get('n_left_out', 0)} of {s.get('n_fits', '?')} fits left out of the "
                         f"plain mean and tests by status ({left or 'none'}); censored ones enter the censored-data (Tobit) "
                         "estimates at their bounds and a bound-substitution sensitivity test (docs/statistics.md, "
                         "'Censored thresholds')." + _open_intervals(s.get("fit_intervals")))
    o = studies.get("ordinal")
    if o is not None:
        lines.append(f"- Ordinal post-hoc: paired t-tests, Bonferroni over {o.get('bonferroni_family_text', '?')}; "
                     "set with `analysis/fig_ordinal_depth.py --bonferroni-family per_level|all`.")
    e = studies.get("egocentric")
    if e is not None:
        lines.append("- Egocentric: reach and target along the horizontal eye-to-target direction (as the supplement), as "
                     "fractions of arm reach. Primary test: linear mixed model with a random intercept and slope per "
                     "participant; the paper's pooled multiple regression (every reach independent) beside it.")
    lines.append("")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "results/summary.md")
    p.add_argument("--protocols", type=Path, default=Path("protocols"), help="the paper's protocol files "
                   "(protocols/<name>.yaml); their hashes pick the paper's results")
    args = p.parse_args(argv)
    out = args.out or args.results / "summary.md"
    failed = failed_studies()
    found = [(path, payload) for path, payload in study_results(args.results) if payload["study"] not in failed]
    not_analysed = failed_lines(failed, args.results)
    for study in failed:
        print(f"[psyop] {study}: not in the summary (its analysis failed in this run)", file=sys.stderr)
    if not found:
        raise UserError("no study results here; run the analysis scripts first (make figures)", str(args.results))
    studies, others = split_paper(found, paper_hashes(args.protocols))
    for path in write_study_summaries(others, args.results, args.data):
        print(f"[psyop] {path} (not a paper protocol: not in the paper's rows)", file=sys.stderr)
    simulated = any(bool(s.get("simulated")) for s in studies.values())
    rows = rows_for(studies)
    lines = ["# Statistics summary, beside the paper", ""]
    if simulated:
        lines += ["**Simulated data**: psyop's numbers come from simulated sessions, not participants; agreement "
                  "shows the analysis reproduces the paper's conclusions from data generated to resemble it.", ""]
    agree = sum(r["agrees"] == "yes" for r in rows)
    judged = sum(r["agrees"] != "n/a" for r in rows)
    lines += [f"Paper: {PAPER_REFERENCE}. **{agree} of {judged} statistics judged agree with the paper** "
              f"({len(rows) - judged} not judged). Rows come only from sessions of the paper's protocols "
              "(protocols/*.yaml, by hash).", "",
              f"Criterion: {CRITERION}", "",
              "| study | statistic | paper | psyop | agrees | criteria |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['study'].split('_')[0]} | {r['statistic']} | {r['paper']} | {r['psyop']} | {r['agrees']} "
                     f"| {r['criteria']} |")
    lines.append("")
    lines += not_analysed
    lines += versions_lines([p for _, p in found])
    lines += _methods(studies)
    lines += quality_lines(args.results, sorted({str(s.get("study")) for s in studies.values()}))
    lines += display_lines(args.data, sorted({str(s.get("study")) for s in studies.values()}))
    lines += ["## Every statistic psyop computed", ""]
    for name in PAPER_PROTOCOLS:
        if name in studies:
            lines += _statistics(studies[name], name)
    write_text(out, "\n".join(lines) + "\n")
    write_json(out.with_suffix(".json"), {
        "simulated": simulated, "agreement_criterion": CRITERION, "paper_comparison": rows,
        "summary": {n: s.get("summary", {}) for n, s in studies.items()}, "studies": studies,
    })
    return 0


if __name__ == "__main__":
    sys.exit(run(main))

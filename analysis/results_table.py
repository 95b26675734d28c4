"""Collect every study's statistics into results/summary.md (paper-form strings) and summary.json.

Reads results/{detection_thresholds,discrimination_fit,ordinal,egocentric,realism}.json
(whichever exist) and, if present, the fit caches for per-fit flags.
    python analysis/results_table.py --results results --out results/summary.md
"""

from __future__ import annotations

import json
import sys

from _common import parser, write_json

STUDY_FILES = ["detection_thresholds", "discrimination_fit", "ordinal", "egocentric", "realism"]


def main(argv: list[str] | None = None) -> int:
    args = parser(__doc__, "results/summary.md").parse_args(argv)
    studies, lines, simulated = {}, ["# Statistics summary", ""], False
    for name in STUDY_FILES:
        path = args.results / f"{name}.json"
        if not path.exists():
            continue
        payload = json.loads(path.read_text())
        studies[name] = payload
        simulated |= bool(payload.get("simulated"))
        lines += [f"## {payload.get('study', name)} (n = {payload.get('n_subjects', '?')})", ""]
        lines += [f"- {k}: {v}" for k, v in payload.get("summary", {}).items()]
        for key in ("flagged", "dropped"):
            if payload.get(key):
                lines.append(f"- {key}: " + "; ".join(json.dumps(x, sort_keys=True) for x in payload[key]))
        lines.append("")
    if not studies:
        print(f"no study results in {args.results}", file=sys.stderr)
        return 1
    if simulated:
        lines.insert(1, "\n**SIMULATED DATA**: these numbers come from simulated sessions, not participants.\n")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    write_json(args.out.with_suffix(".json"), {
        "simulated": simulated, "summary": {n: s.get("summary", {}) for n, s in studies.items()}, "studies": studies,
    })
    return 0


if __name__ == "__main__":
    sys.exit(main())

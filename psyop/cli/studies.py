"""``psyop studies DATA``: every study in a data root, its response kind and the analysis that
``make figures`` runs for it; ``--make-rules FILE`` writes those as make rules (figures.mk includes them).

Studies are found in ``DATA/<study>/`` by their sessions, and their analysis chosen by their
response kind (psyop.statistics.studies), never by name:

- two-interval: the psychometric fits (results/<study>_fits.csv), the thresholds figure
  (figures/<study>_thresholds.png: thresholds by condition with an rm-ANOVA; with the linear fit
  of analysis/fig_discrimination_thresholds.py for sessions of the paper's discrimination protocol,
  identified by its hash) and every psychometric function (figures/supp_psychometric_<study>.png);
- left/right nearer: figures/<study>_depth.png; reach: figures/<study>_reach.png;
  pairwise preference: figures/<study>_preferences.png; with/against (NC calibration):
  figures/<study>_pss.png.
"""

from __future__ import annotations

import argparse
import hashlib
from dataclasses import dataclass
from pathlib import Path

#: Sessions of this shipped protocol (by hash) get the linear-fit thresholds figure.
LINEAR_FIT_PROTOCOLS = ("discrimination.yaml",)
KIND_NAMES = {"2afc_interval": "two-interval", "near_side": "left/right nearer", "preference": "pairwise preference",
              "reach": "reach", "with_against": "with/against (NC calibration)"}


@dataclass(frozen=True)
class Target:
    """One output of a study's analysis: the file (relative to $(FIGDIR) or $(RESULTS)), the script
    and its extra make prerequisites and arguments."""

    output: str
    script: str
    prerequisites: str
    arguments: str
    kind: str = "figure"  # figure (in $(FIGDIR)) or fits (in $(RESULTS))


def make_escaped(path: Path) -> str:
    r"""``path`` as one word in a make prerequisite list (spaces, ``#``, ``:`` and ``$`` escaped).

    Examples
    --------
    >>> make_escaped(Path("my data/sub-1/ses-1/trials.parquet"))
    'my\\ data/sub-1/ses-1/trials.parquet'
    """
    text = path.as_posix().replace("$", "$$")
    for character in " #:":
        text = text.replace(character, "\\" + character)
    return text


def targets_for(study: str, kind: str, linear_fit: bool, trials: str = "") -> list[Target]:
    """The analysis of one study, by its response kind; ``trials`` is its sessions' trials.parquet
    files as make prerequisites (:func:`make_escaped`, so a data root may hold spaces).

    Examples
    --------
    >>> [t.output for t in targets_for("mine", "near_side", False)]
    ['mine_depth.png']
    """
    fits = f"$(RESULTS)/{study}_fits.csv"
    common = f'--study {study} --data "$(DATA)" --results "$(RESULTS)"'

    if kind == "2afc_interval":
        script = "analysis/fig_discrimination_thresholds.py" if linear_fit else "analysis/fig_detection_thresholds.py"
        return [Target(f"{study}_fits.csv", "analysis/fit_psychometric.py", f"$(STATS_SRC) {trials}",
                       f"{common} --n-jobs $(JOBS)", kind="fits"),
                Target(f"{study}_thresholds.png", script, f"{fits} $(DRAW_SRC)", f'{common} --fits "{fits}"'),
                Target(f"supp_psychometric_{study}.png", "analysis/supp_psychometric_functions.py",
                       f"{fits} $(DRAW_SRC)", f'{common} --fits "{fits}"')]
    figure = {"near_side": ("depth", "analysis/fig_ordinal_depth.py"), "reach": ("reach", "analysis/fig_egocentric_reach.py"),
              "preference": ("preferences", "analysis/fig_realism.py"),
              "with_against": ("pss", "analysis/nc_calibration.py")}[kind]
    return [Target(f"{study}_{figure[0]}.png", figure[1], f"{trials} $(DRAW_SRC)", common)]


def make_rules(data: Path, protocols: Path) -> tuple[str, list[str]]:
    """(the make fragment, one line per study saying what it builds)."""
    from psyop.statistics.studies import studies_in

    linear = set()
    for name in LINEAR_FIT_PROTOCOLS:
        path = protocols / name
        if path.is_file():
            linear.add(hashlib.sha256(path.read_bytes().decode("utf-8").encode("utf-8")).hexdigest())
    rules = ["# written by `psyop studies --make-rules`: one block per study in the data root", ""]
    said = []
    for facts in studies_in(data):
        uses_linear = bool(facts.protocol_sha256) and set(facts.protocol_sha256) <= linear
        sessions = sorted((data / facts.name).glob("sub-*/ses-*/trials.parquet"))
        prerequisites = " ".join(make_escaped(p) for p in sessions)
        targets = targets_for(facts.name, facts.kind, uses_linear, prerequisites) + [Target(  # issue 27: gaze quality
            f"{facts.name}_gaze_quality.png", "analysis/gaze_quality.py", f"{prerequisites} $(QUALITY_SRC)",
            f'--study {facts.name} --data "$(DATA)" --results "$(RESULTS)"')]
        figures = [t for t in targets if t.kind == "figure"]
        rules.append("STUDY_FIGURES += " + " ".join(f"$(FIGDIR)/{t.output}" for t in figures))
        for t in targets:
            where = "$(RESULTS)" if t.kind == "fits" else "$(FIGDIR)"
            label = f"fitting psychometric functions: {facts.name}" if t.kind == "fits" else \
                f"{facts.name} ({KIND_NAMES[facts.kind]}): $@"
            rules += [f"{where}/{t.output}: {t.script} {t.prerequisites}", f'\t@mkdir -p "{where}"',
                      f"\t@echo \"[psyop] {label}\"", f'\t@"$(ANALYSE)" "$<" {t.arguments} --out "$@"', ""]
        said.append(f"{facts.name} ({KIND_NAMES[facts.kind]}): " + ", ".join(t.output for t in figures))
    return "\n".join(rules) + "\n", said


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "studies", help="list the studies of a data root with their response kind and analysis",
        description="Every study in DATA (by its sessions), its response kind and the figures `make figures` "
        "builds for it. --make-rules FILE writes the make rules (figures.mk includes them).")
    parser.add_argument("data", type=Path, nargs="?", default=Path("data"), help="data root (default data/)")
    parser.add_argument("--make-rules", type=Path, default=None, help="write the make rules to this file "
                        "(rewritten only when they change)")
    parser.add_argument("--protocols", type=Path, default=Path("protocols"), help="the paper's protocols")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    text, said = make_rules(args.data, args.protocols)
    for line in said:
        print(f"[psyop] study {line}")
    if not said:
        print(f"[psyop] {args.data}/: no studies")
    if args.make_rules is not None:
        args.make_rules.parent.mkdir(parents=True, exist_ok=True)
        if not args.make_rules.exists() or args.make_rules.read_text() != text:
            args.make_rules.write_text(text)
    return 0

"""Perceptual realism (pairwise preference): how often the first mode of each pair was chosen,
one-tailed binomial tests against 50 %. The pairs are those the study showed, each written with the
mode the paper expects to win first (ocular, then reversed, then conventional). Writes
results/<study>_preferences.csv and results/<study>.json.
"""

from __future__ import annotations

import sys

from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_preferences
from psyop.statistics.binomial import pairwise_preferences
from psyop.statistics.dataset import load_dataset
from psyop.statistics.formatting import format_binomial
from psyop.statistics.studies import study_facts

#: Which mode of a pair is written first (the paper's: ocular over conventional, reversed over
#: conventional, ocular over reversed).
FIRST_RANK = {"ocular": 0, "reversed": 1, "conventional": 2}


def study_pairs(mode_a, mode_b) -> list[tuple[str, str]]:
    """The distinct pairs shown, each ordered by :data:`FIRST_RANK` (then by name).

    Examples
    --------
    >>> study_pairs(["conventional", "reversed", "ocular"], ["ocular", "ocular", "conventional"])
    [('ocular', 'conventional'), ('ocular', 'reversed')]
    >>> study_pairs(["conventional", "reversed", "ocular"], ["reversed", "ocular", "conventional"])
    [('ocular', 'conventional'), ('reversed', 'conventional'), ('ocular', 'reversed')]
    """
    def key(mode: str) -> tuple[int, str]:
        return (FIRST_RANK.get(mode, len(FIRST_RANK)), mode)

    pairs = {tuple(sorted((str(a), str(b)), key=key)) for a, b in zip(mode_a, mode_b)}
    return sorted(pairs, key=lambda p: (-key(p[1])[0], key(p[1])[1], key(p[0])))


def main(argv: list[str] | None = None) -> int:
    args = parser(__doc__, "figures/{study}_preferences.png", study="realism").parse_args(argv)
    facts = study_facts(args.data, args.study)
    require_kind(facts, "pairwise_preference", "fig_realism.py")
    ds = load_dataset(args.data, args.study)
    require_columns(ds.trials, ["mode_a", "mode_b", "chosen_mode"], str(args.data / args.study),
                    "a pairwise-preference log has mode_a, mode_b and chosen_mode")
    prefs = pairwise_preferences(ds.trials, study_pairs(ds.trials["mode_a"], ds.trials["mode_b"]))
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(prefs, results_file(args.results, args.study, "preferences", "csv"))
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "preferences", args.pool_protocols), "simulated": ds.simulated,
        "n_subjects": int(ds.trials["participant"].nunique()), "preferences": prefs.to_dict("records"),
        "summary": {f"{args.study}: {r['first']} over {r['second']}": format_binomial(r) for _, r in prefs.iterrows()},
    })
    save_figure(plot_preferences(prefs, simulated=ds.simulated), out_path(args))
    return 0


if __name__ == "__main__":
    sys.exit(run(main))

"""Perceptual realism: how often the first mode of each pair was chosen, one-tailed binomial
tests against 50 %. Writes results/realism_preferences.csv and results/realism.json.
"""

from __future__ import annotations

import sys

from _common import parser, run, write_csv, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_preferences
from psyop.statistics.binomial import pairwise_preferences
from psyop.statistics.dataset import load_dataset
from psyop.statistics.formatting import format_binomial

PAIRS = [("ocular", "conventional"), ("reversed", "conventional"), ("ocular", "reversed")]


def main(argv: list[str] | None = None) -> int:
    args = parser(__doc__, "figures/fig_realism.png", study="realism").parse_args(argv)
    ds = load_dataset(args.data, args.study)
    prefs = pairwise_preferences(ds.trials, PAIRS)
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(prefs, args.results / "realism_preferences.csv")
    write_json(args.results / "realism.json", {
        "study": "realism", "simulated": ds.simulated, "n_subjects": int(ds.trials["participant"].nunique()),
        "preferences": prefs.to_dict("records"),
        "summary": {f"realism: {r['first']} over {r['second']}": format_binomial(r) for _, r in prefs.iterrows()},
    })
    save_figure(plot_preferences(prefs, simulated=ds.simulated), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))

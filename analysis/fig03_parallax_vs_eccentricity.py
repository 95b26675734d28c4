"""Paper Fig. 3: ocular parallax vs eccentricity, with MAR and the Vive Pro pixel size."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from psyop.figures.optics_figures import plot_parallax_vs_eccentricity
from psyop.figures.output import save_figure

from _common import run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("figures/fig03_parallax_vs_eccentricity.png"))
    args = parser.parse_args(argv)
    save_figure(plot_parallax_vs_eccentricity(), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))

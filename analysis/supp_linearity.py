"""Supplement Fig. 1: ocular parallax vs surface separation in metres and in diopters."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from psyop.figures.optics_figures import plot_linearity
from psyop.figures.output import save_figure

from _common import run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("figures/supp_linearity.png"))
    args = parser.parse_args(argv)
    save_figure(plot_linearity(), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))

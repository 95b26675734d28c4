"""Writing figures: the one place that decides formats, resolution and cleanup."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.figure import Figure


def save_figure(fig: Figure, out_png: Path, dpi: int = 150) -> list[Path]:
    """Write ``out_png`` and a PDF with the same stem beside it, close the figure, and
    return both paths."""
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    pdf = out_png.with_suffix(".pdf")
    fig.savefig(out_png, dpi=dpi, bbox_inches="tight")
    fig.savefig(pdf, bbox_inches="tight")
    plt.close(fig)
    return [out_png, pdf]

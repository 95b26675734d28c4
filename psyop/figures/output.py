"""Writing figures: the one place that decides formats, resolution and cleanup."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from psyop.atomic import write_atomic


def save_figure(fig: Figure, out_png: Path, dpi: int = 150) -> list[Path]:
    """Write ``out_png`` and a PDF with the same stem beside it (each atomically), close the
    figure, and return both paths."""
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    pdf = out_png.with_suffix(".pdf")
    try:  # each file is whole or absent (psyop.atomic): a full disk never leaves a truncated figure
        write_atomic(out_png, lambda handle: fig.savefig(handle, format="png", dpi=dpi, bbox_inches="tight"))
        write_atomic(pdf, lambda handle: fig.savefig(handle, format="pdf", bbox_inches="tight"))
    finally:
        plt.close(fig)
    return [out_png, pdf]

"""Figures drawn from the analytic optics models: paper Fig. 3 and supplement Fig. 1.

Each ``plot_*`` function returns a matplotlib Figure and does no I/O; :func:`psyop.figures.output.save_figure`
writes a figure as PNG plus a PDF beside it. Uses the Agg backend through
``matplotlib.figure.Figure`` (no pyplot state).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from matplotlib import rc_context
from matplotlib.figure import Figure

from psyop.figures.labels import STYLE, display_label

from psyop.optics.display import VIVE_PRO, DisplayProfile
from psyop.optics.eye_models import DEFAULT_EYE_MODEL
from psyop.optics.parallax import (
    bingham_parallax_rad,
    minimum_angle_of_resolution_deg,
    ocular_parallax_exact_rad,
)
from psyop.optics.pixels import pixel_angles

ARCMIN_PER_RAD = 180.0 / np.pi * 60.0


def plot_parallax_vs_eccentricity(
    relative_D: Sequence[float] = (0.5, 1.0, 2.0, 3.0),
    nc_m: float = DEFAULT_EYE_MODEL.nc_m,
    display: DisplayProfile = VIVE_PRO,
    max_eccentricity_deg: float = 40.0,
    foveal_max_deg: float = 5.0,
) -> Figure:
    """Paper Fig. 3: ocular parallax (arcmin) against eccentricity for two points ``relative_D``
    apart (the far one at optical infinity, exact model), with Guenter's MAR and the display's
    pixel size. Left: foveal region, semi-log; right: up to ``max_eccentricity_deg``."""
    with rc_context(STYLE):
        fig = Figure(figsize=(10.0, 4.2), layout="constrained")
        ax_fovea, ax_full = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.6]})
        colours = [f"C{i}" for i in range(len(relative_D))]
        for ax, e_max in ((ax_fovea, foveal_max_deg), (ax_full, max_eccentricity_deg)):
            ecc = np.linspace(0.0, e_max, 400)
            for rel, colour in zip(relative_D, colours):
                parallax = ocular_parallax_exact_rad(ecc, rel, 0.0, nc_m) * ARCMIN_PER_RAD
                ax.plot(ecc, parallax, color=colour, label=f"{rel:g} D separation")
            ax.plot(ecc, minimum_angle_of_resolution_deg(ecc) * 60.0, "r--", label="MAR (Guenter et al.)")
            # the paper's pixel size is the row average; the pixel on the display's axis is larger
            # (psyop.optics.pixels; docs/optics.md, "Pixel angles")
            ax.axhline(display.arcmin_per_px, color="b", ls="--",
                       label=f"{display_label(display.name)} pixel, row average ({display.arcmin_per_px:.2f}')")
            centre_px = pixel_angles(display).centre.width_arcmin
            ax.axhline(centre_px, color="b", ls=":", label=f"{display_label(display.name)} centre pixel ({centre_px:.2f}')")
            ax.set_xlim(0.0, e_max)
            ax.set_xlabel("eccentricity (deg)")
            ax.set_ylabel("ocular parallax (arcmin)")
            ax.grid(True, alpha=0.3)
        for rel, colour in zip(relative_D, colours):
            below = parallax_below_mar_deg(rel, nc_m, max_eccentricity_deg)
            if below is not None:
                mar = float(minimum_angle_of_resolution_deg(np.array([below]))[0] * 60.0)
                ax_full.axvline(below, color=colour, ls=":", lw=1.0)
                ax_full.annotate(f"{rel:g} D falls below MAR\nbeyond {below:.1f} deg", (below, mar),
                                 xytext=(below + 1.5, mar * 1.6 + 0.5), color=colour, fontsize=9,
                                 arrowprops=dict(arrowstyle="->", color=colour, lw=0.9))
        ax_fovea.set_yscale("log")
        ax_fovea.set_ylim(0.01, 20.0)
        ax_fovea.set_title("foveal region (semi-log)")
        ax_full.set_ylim(0.0, None)
        ax_full.set_title(f"up to {max_eccentricity_deg:g} deg (NC = {nc_m * 1000:.4f} mm)")
        ax_full.legend(loc="upper left")
    return fig


def parallax_below_mar_deg(relative_D: float, nc_m: float = DEFAULT_EYE_MODEL.nc_m,
                           max_eccentricity_deg: float = 40.0) -> float | None:
    """The eccentricity beyond which ocular parallax of ``relative_D`` stays below Guenter's MAR
    (the last crossing from above), or None when it never falls below within range."""
    ecc = np.linspace(0.0, max_eccentricity_deg, 4001)
    diff = ocular_parallax_exact_rad(ecc, relative_D, 0.0, nc_m) * ARCMIN_PER_RAD - minimum_angle_of_resolution_deg(ecc) * 60.0
    above = diff > 0
    if not above.any() or above[-1]:
        return None
    last = int(np.flatnonzero(above)[-1])
    x0, x1, d0, d1 = ecc[last], ecc[last + 1], diff[last], diff[last + 1]
    return float(x0 + (x1 - x0) * d0 / (d0 - d1))


def plot_linearity(
    back_D: Sequence[float] = (1.0, 2.0, 3.0),
    max_separation_D: float = 2.0,
    rotation_deg: float = 15.0,
    nc_m: float = DEFAULT_EYE_MODEL.nc_m,
) -> Figure:
    """Supplement Fig. 1: parallax at an occluding edge (Bingham's geometry, ``rotation_deg``)
    against the depth separation of the two surfaces, in metres (left) and diopters (right)."""
    with rc_context(STYLE):
        fig = Figure(figsize=(10.0, 4.0), layout="constrained")
        ax_m, ax_d = fig.subplots(1, 2)
        for back, colour in zip(back_D, (f"C{i}" for i in range(len(back_D)))):
            sep_D = np.linspace(0.0, max_separation_D, 200)
            front_m = 1.0 / (back + sep_D)
            parallax = bingham_parallax_rad(1.0 / back, front_m, rotation_deg, nc_m) * ARCMIN_PER_RAD
            ax_m.plot(1.0 / back - front_m, parallax, color=colour, label=f"back surface at {back:g} D")
            ax_d.plot(sep_D, parallax, color=colour, label=f"back surface at {back:g} D")
        ax_m.set_xlabel("separation (m)")
        ax_d.set_xlabel("separation (D)")
        for ax in (ax_m, ax_d):
            ax.set_ylabel("ocular parallax (arcmin)")
            ax.set_xlim(0.0, None)
            ax.set_ylim(0.0, None)
            ax.grid(True, alpha=0.3)
            ax.legend()
        ax_m.set_title("metric separation: not linear")
        ax_d.set_title(f"dioptric separation: linear ({rotation_deg:g} deg rotation)")
    return fig

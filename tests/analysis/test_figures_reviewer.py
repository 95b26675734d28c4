"""What a reviewer checks on the study figures: one simulated label, readable names, '±', error-bar
type stated, CIs not below 0 D, legends for every colour, >= 9 pt text, Fig. 3's MAR crossing,
egocentric as participant means."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from matplotlib.text import Text

from psyop.figures.optics_figures import parallax_below_mar_deg, plot_parallax_vs_eccentricity
from psyop.figures.study_figures import (
    SIMULATED_LABEL, plot_ordinal, plot_preferences, plot_psychometric_grid, plot_reach, plot_thresholds,
)
from psyop.statistics import simulate as sim
from psyop.statistics.anova import cell_means, posthoc_paired
from psyop.statistics.binomial import pairwise_preferences
from psyop.statistics.regression import linear_fits_by


def _texts(fig) -> list[Text]:
    fig.canvas.draw()
    return [t for t in fig.findobj(Text) if t.get_text().strip() and t.get_visible()]


def _fits() -> pd.DataFrame:
    rows = []
    for i, s in enumerate(["S01", "S02", "S03"]):
        for back in (1.0, 2.0, 3.0):
            rows.append({"participant": s, "back_D": back, "status": "ok", "threshold_D": 0.3 + 0.05 * i,
                         "threshold_ci_low_D": -0.1, "threshold_ci_high_D": 0.7, "threshold_bound_D": np.nan,
                         "flags": "ci_below_range", "location_D": 0.3, "width_D": 0.5, "lapse": 0.02,
                         "level_min_D": 0.0, "level_max_D": 1.0})
    rows[0].update(status="censored_below", threshold_D=np.nan, threshold_bound_D=0.0, flags="censored_below")
    rows[1].update(status="no_upper_bound", threshold_ci_high_D=np.inf, flags="no_upper_bound")
    return pd.DataFrame(rows)


def _figures():
    rng = np.random.default_rng(0)
    cells = cell_means(sim.simulate_ordinal(rng, n_subjects=8), "correct", ["mode", "separation_D"])
    reach = sim.simulate_reach(rng, n_subjects=5)
    reach["reach_fraction"] = reach["reach_m"] / reach["arm_reach_m"]
    prefs = pairwise_preferences(sim.simulate_realism(rng, n_subjects=5),
                                 [("ocular", "conventional"), ("reversed", "conventional"), ("ocular", "reversed")])
    blocks = pd.DataFrame([{"participant": s, "back_D": b, "level_D": lv, "n_correct": 10, "n_total": 15}
                           for s in ("S01", "S02", "S03") for b in (1.0, 2.0, 3.0) for lv in (0, 0.5, 1.0)])
    return {
        "thresholds": plot_thresholds(_fits(), "back_D", "back surface distance (D)", "Detection", simulated=True),
        "ordinal": plot_ordinal(cells, posthoc_paired(cells, "correct", "mode", by="separation_D"), simulated=True),
        "reach": plot_reach(reach, linear_fits_by(reach, "target_fraction", "reach_fraction", "rendering"), simulated=True),
        "preferences": plot_preferences(prefs, simulated=True),
        "psychometric": plot_psychometric_grid(blocks, _fits(), "back_D", "Psychometric functions", simulated=True),
        "fig3": plot_parallax_vs_eccentricity(),
    }


@pytest.fixture(scope="module")
def figures():
    figs = _figures()
    yield figs
    for f in figs.values():
        plt.close(f)


def test_one_simulated_label_and_no_code_names(figures):
    for name, fig in figures.items():
        texts = [t.get_text() for t in _texts(fig)]
        joined = " ".join(texts)
        if name != "fig3":
            assert sum(SIMULATED_LABEL.lower() in t.lower() for t in texts) == 1, (name, texts)
        for code in ("back_D", "offset_D", "sub-", "+-", "vive_pro", "separation_D ="):
            assert code not in joined, (name, code)


def test_text_is_at_least_9_pt(figures):
    for name, fig in figures.items():
        small = [(t.get_text(), t.get_fontsize()) for t in _texts(fig) if t.get_fontsize() < 9]
        assert not small, (name, small[:5])


def test_error_bar_type_is_stated_with_plus_minus(figures):
    for name in ("thresholds", "ordinal", "preferences"):
        joined = " ".join(t.get_text() for t in _texts(figures[name]))
        assert "± SE across participants" in joined, name
    assert "± 95 % CI" in " ".join(t.get_text() for t in _texts(figures["thresholds"]))
    assert "Bonferroni" in " ".join(t.get_text() for t in _texts(figures["ordinal"]))
    assert "binomial" in " ".join(t.get_text() for t in _texts(figures["preferences"]))


def test_cis_are_clipped_at_zero_with_a_marker_and_censored_fits_drawn_as_bounds(figures):
    fig = figures["thresholds"]
    ax = fig.axes[0]
    assert ax.get_ylim()[0] >= 0.0
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "CI clipped at 0 D" in labels and "CI without upper bound" in labels
    assert any(lbl.startswith("censored") for lbl in labels)
    for line in ax.get_lines():
        y = np.asarray(line.get_ydata(), float)
        assert np.all(y[np.isfinite(y)] >= 0.0)


def test_every_colour_has_a_legend(figures):
    assert figures["preferences"].axes[0].get_legend() is not None
    assert figures["ordinal"].axes[0].get_legend() is not None
    assert figures["reach"].legends


def test_fig3_marks_where_3D_falls_below_the_mar():
    crossing = parallax_below_mar_deg(3.0)
    assert crossing is not None and 20 < crossing < 40
    fig = plot_parallax_vs_eccentricity()
    assert any("3 D falls below MAR" in t.get_text() for t in _texts(fig))
    plt.close(fig)


def test_egocentric_shows_participant_means_not_every_reach(figures):
    fig = figures["reach"]
    dots = sum(len(line.get_xdata()) for ax in fig.axes for line in ax.get_lines() if line.get_marker() == "o")
    assert dots == 5 * 6 * 2  # participants x targets x conditions (the old plot had every reach)


def test_psychometric_panels_share_limits_without_shared_axes(figures):
    """Every panel has the same y limits (below-chance points visible) and only the first column
    draws y tick labels, as sharey would, without shared axes (whose every limit change and draw
    visits all the other panels: quadratic in participants)."""
    fig = figures["psychometric"]
    fig.canvas.draw()
    axes = [ax for ax in fig.axes if ax.get_subplotspec() is not None]
    assert len(axes) == 9
    assert {ax.get_ylim() for ax in axes} == {(0.0, 1.02)}
    assert all(len(ax.get_shared_y_axes().get_siblings(ax)) == 1 for ax in axes)
    for ax in axes:
        labelled = [t.get_text() for t in ax.get_yticklabels() if t.get_visible() and t.get_text()]
        assert bool(labelled) == ax.get_subplotspec().is_first_col(), labelled

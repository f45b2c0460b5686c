"""Figures a reader can read: titles inside the figure, labelled axes, ties greyed,
datasets in one order, and no label over a point."""
import numpy as np
import pandas as pd
import pytest

from analysis import figures
from analysis.data import ordered_datasets
from lgp.paper import TRIAL_IDS


@pytest.fixture
def drawn(monkeypatch):
    """Every Figure the plotting functions finish, after it was saved (laid out)."""
    real, figs = figures._finish, []

    def keep(fig, *a, **k):
        paths = real(fig, *a, **k)
        figs.append(fig)
        return paths

    monkeypatch.setattr(figures, "_finish", keep)
    return figs


def _summary(datasets):
    rows = [(d, m, 0.5, 0.3, 0.7, 200) for d in datasets for m in ("full", "effort", "risk")]
    return pd.DataFrame(rows, columns=["dataset", "model", "r_median", "r_low", "r_high", "n_boot"])


def _inside(fig, artist) -> bool:
    fig.canvas.draw()
    box, frame = artist.get_window_extent(fig.canvas.get_renderer()), fig.bbox
    return box.x0 >= frame.x0 - 0.5 and box.x1 <= frame.x1 + 0.5 and box.y0 >= frame.y0 - 0.5 and box.y1 <= frame.y1 + 0.5


@pytest.mark.parametrize("datasets", [["time"], pytest.param(["simulated-build"], marks=pytest.mark.slow),
                                      pytest.param(["difficulty", "time"], marks=pytest.mark.slow),
                                      ["simulated-difficulty", "simulated-time", "simulated-build"]])
def test_figure_4_title_lies_inside_the_figure(datasets, tmp_path, drawn):
    figures.plot_model_correlations(_summary(datasets), tmp_path)
    (fig,) = drawn
    assert fig.get_suptitle() and _inside(fig, fig._suptitle)
    labels = [t.get_text() for t in fig.axes[0].get_xticklabels()]
    assert labels == [figures.dataset_label(d) for d in ordered_datasets(datasets)]


@pytest.mark.slow  # draws the full pairs figure
def test_effort_risk_pairs_has_units_on_its_y_axes_and_greys_a_tie_like_a_reversal(tmp_path, drawn):
    E = pd.Series({t: 1.0 + k for k, t in enumerate(TRIAL_IDS)})
    E["6H"] = E["6E"] * (1 + 1e-5)  # a tie under analysis.pairs.TIE_REL
    E["11H"] = E["11E"] * 0.99  # a reversal
    risk = pd.DataFrame([(t, 0.065, 0.0) for t in TRIAL_IDS], columns=["trial", "sigma", "risk"])
    betas = {"time": (0, 1, 4), "difficulty": (0, 1, 3)}
    figures.plot_effort_risk(E, risk, 0.065, tmp_path, betas=betas)
    (fig,) = drawn
    effort_ax, risk_ax, *fits = fig.axes
    assert effort_ax.get_ylabel() == "E (J s)" and "R (fraction" in risk_ax.get_ylabel()
    assert all(ax.get_ylabel() for ax in fits)
    grey = sorted(round((p.get_x() + p.get_width() / 2)) for p in effort_ax.patches)
    assert grey == [6, 11]
    assert "tied: 6" in effort_ax.get_title() and "reversed: 11" in effort_ax.get_title()
    # fitted panels in the paper's dataset order, whatever the order of the dict
    assert "Estimated Difficulty" in fits[0].get_title() and "Estimated Time" in fits[1].get_title()
    assert _inside(fig, fig._suptitle)


def test_chosen_sigma_is_named_in_the_legend_not_over_the_points(tmp_path, drawn):
    sigmas = np.round(np.arange(0.05, 0.101, 0.005), 3)
    profile = pd.DataFrame([(d, s, 0.5 + (s - 0.065) ** 2) for d in ("time", "build") for s in sigmas],
                           columns=["dataset", "sigma", "rmse"])
    choice = pd.DataFrame([("pooled", 0.065, 0.5, "least mean RMSE")], columns=["dataset", "sigma", "rmse", "rule"])
    figures.plot_sigma_profile(profile, tmp_path, choice)
    (fig,) = drawn
    ax = fig.axes[0]
    assert not ax.texts  # nothing written on the axes
    assert "chosen sigma = 0.065 d" in [t.get_text() for t in ax.get_legend().get_texts()]
    labels = [t.get_text() for t in ax.get_legend().get_texts()][:2]
    assert labels == ["Estimated Time", "Build Time"]  # the paper's order, not alphabetical


@pytest.mark.parametrize("sigmas", [[0.065], [0.05, 0.065, 0.08]])
def test_risk_over_sigma_draws_each_pairs_risks_also_at_a_single_sigma(tmp_path, sigmas):
    # A run at one sigma (--sigmas 0.065) has one point per curve: the figure must
    # still show it (a line through one point draws nothing). Pair 4's H risk 0.5 is
    # read back from the PNG's pixels in its panel, under the legend.
    from matplotlib.colors import to_rgb
    from PIL import Image

    from lgp.app.over_sigma import HARD, plot_risk_over_sigma

    rows = [{"pair": p, "sigma": s, "risk_E": 0.0, "risk_E_low": 0.0, "risk_E_high": 0.05,
             "risk_H": 0.5 if p == 4 else 0.0, "risk_H_low": 0.4 if p == 4 else 0.0, "risk_H_high": 0.6 if p == 4 else 0.05,
             "holds": p == 4} for p in range(1, 13) for s in sigmas]
    png = plot_risk_over_sigma(pd.DataFrame(rows), tmp_path / "r.png")
    rgb = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w, _ = rgb.shape
    panel = rgb[int(0.12 * h):int(0.5 * h), int(3 / 6 * w):int(4 / 6 * w)]  # first row, fourth panel: pair 4
    blue = (np.abs(panel - np.array(to_rgb(HARD)) * 255).sum(axis=2) < 60).sum()
    assert blue > 30, blue

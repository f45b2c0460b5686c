"""Figures of the Results section, written as PNG and PDF.

* `plot_trial_means`: Figure 3 analog, mean z-scored responses per trial with
  95% bootstrap intervals and the fitted model (easy red, hard blue).
* `plot_model_correlations`: Figure 4 analog, bootstrap correlations of the
  three models per dataset.
* `plot_sigma_profile`: RMSE of Eq. 1 against sigma.
* `plot_effort_risk`: effort, risk and (optionally) full-model cost per easy/hard
  pair; needs no human data.

Figures from simulated participants (datasets ``simulated-...``) say
"SIMULATED participants (not human data)" in the title and have "simulated" in
their file names. Drawing uses matplotlib's object API with the Agg canvas, so
importing this module never changes the caller's pyplot backend.
"""
from __future__ import annotations

from lgp.atomic import atomic_path

from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from analysis.data import is_simulated_dataset, ordered_datasets
from analysis.data.trialset import pair_numbers, trial_ids
from analysis.models import MODEL_LABELS, MODELS, effort_per_trial, full_model_cost, risk_at_sigma
from analysis.pairs import PAPER_NO_DIFFERENCE, TIE_REL, pair_table
from analysis.spec import RISK_MEASURES, ModelSpec

EASY_COLOUR = "tab:red"
HARD_COLOUR = "tab:blue"
MODEL_COLOURS = {"full": "black", "effort": "tab:green", "risk": "tab:orange",
                 # heuristic baselines (analysis.spec): no physics; the composites in strong colours
                 "height": "#9ecae1", "blocks": "#c6dbef", "stacked": "#6baed6", "distance": "#bcbddc",
                 "actions": "#dadaeb", "depth": "#4292c6",
                 "effort+height": "tab:purple", "effort+stacked": "tab:brown"}


#: Colours of the build-risk measures standing in for R (``full[max]``, ...): one per measure.
MEASURE_COLOURS = ("tab:gray", "tab:red", "tab:cyan", "tab:olive", "tab:pink", "tab:blue", "goldenrod")


def model_colour(model: str) -> str:
    """A model's colour: its own (MODEL_COLOURS), or for a build-risk model
    (``full[max]``) one colour per risk measure (RISK_MEASURES order)."""
    if model in MODEL_COLOURS:
        return MODEL_COLOURS[model]
    spec = ModelSpec.parse(model)
    if spec.risk is None:
        return MODEL_COLOURS[spec.base]
    return MEASURE_COLOURS[RISK_MEASURES.index(spec.risk) % len(MEASURE_COLOURS)]


def model_label(model: str) -> str:
    """A model's label: MODEL_LABELS, or its base's label with the risk measure (``Full (effort + risk), R = max``)."""
    if model in MODEL_LABELS:
        return MODEL_LABELS[model]
    spec = ModelSpec.parse(model)
    return MODEL_LABELS.get(spec.base, spec.base) + (f", R = {spec.risk}" if spec.risk else "")


def _models_in(summary: pd.DataFrame) -> list[str]:
    """The paper's models first (MODELS), then every other model of the table in its order."""
    present = list(dict.fromkeys(summary["model"]))
    return [m for m in MODELS if m in present] + [m for m in present if m not in MODELS]
SIMULATED_TITLE = "SIMULATED participants (not human data)"
DATASET_LABELS = {"difficulty": "Estimated Difficulty", "time": "Estimated Time",
                  "build": "Build Time"}


def dataset_label(dataset: str) -> str:
    """'time' -> 'Estimated Time'; 'simulated-time' -> 'SIMULATED Estimated Time'."""
    if is_simulated_dataset(dataset):
        base = dataset.split("-", 1)[1]
        return f"SIMULATED {DATASET_LABELS.get(base, base)}"
    return DATASET_LABELS.get(dataset, dataset)


def plot_trial_means(means: pd.DataFrame, predictions: pd.DataFrame, out_dir: str | Path,
                     model: str = "full", stem: str = "fig3_trial_means") -> list[Path]:
    """Figure 3 analog: one panel per dataset.

    `means` has columns dataset, trial, mean_z, ci_low, ci_high
    (`trial_mean_intervals`); `predictions` columns dataset, model, sigma, trial,
    predicted (`fit_models`). Human means are large points joined by solid lines
    within each pair, with 95% CI bars; the `model` fit small points joined by
    dotted lines; easy trials red, hard blue. Returns the PNG and PDF paths.
    """
    datasets = ordered_datasets(means["dataset"].unique())
    fig = Figure(figsize=(11, 2.9 * len(datasets) + 0.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(datasets), 1, squeeze=False)[:, 0]
    x = _trial_x()
    for ax, dataset in zip(axes, datasets):
        m = means[means["dataset"] == dataset].set_index("trial").reindex(list(trial_ids()))
        p = predictions[(predictions["dataset"] == dataset) & (predictions["model"] == model)]
        p = p.set_index("trial").reindex(list(trial_ids()))
        sigma = p["sigma"].iloc[0] if "sigma" in p and len(p) else np.nan
        r = np.corrcoef(p["predicted"], m["mean_z"])[0, 1]
        for k, pair in enumerate(pair_numbers()):
            sl = slice(2 * k, 2 * k + 2)
            ax.plot(x[sl], m["mean_z"].to_numpy()[sl], "-", color="0.45", lw=1.2, zorder=1)
            ax.plot(x[sl] + 0.18, p["predicted"].to_numpy()[sl], ":", color="0.2", lw=1.2, zorder=1)
        for level, colour in (("E", EASY_COLOUR), ("H", HARD_COLOUR)):
            idx = [i for i, t in enumerate(trial_ids()) if t.endswith(level)]
            mm = m["mean_z"].to_numpy()[idx]
            err = np.vstack([mm - m["ci_low"].to_numpy()[idx], m["ci_high"].to_numpy()[idx] - mm])
            ax.errorbar(x[idx], mm, yerr=err, fmt="o", ms=7, color=colour, ecolor=colour,
                        elinewidth=1.2, capsize=2.5, zorder=3)
            ax.plot(x[idx] + 0.18, p["predicted"].to_numpy()[idx], "o", ms=3.5, color=colour,
                    markeredgecolor="black", markeredgewidth=0.4, zorder=4)
        ax.axhline(0, color="0.85", lw=0.8, zorder=0)
        ax.set_xticks(x, list(trial_ids()), fontsize=8)
        ax.set_xlim(x[0] - 0.7, x[-1] + 0.9)
        ax.set_ylabel("mean z-score")
        ax.set_title(f"{dataset_label(dataset)}: {model_label(model)} model, "
                     f"sigma = {sigma:g} d, r = {r:.2f}", fontsize=10)
    handles = [
        Line2D([], [], marker="o", ms=7, color=EASY_COLOUR, ls="", label="easy trial (mean, 95% CI)"),
        Line2D([], [], marker="o", ms=7, color=HARD_COLOUR, ls="", label="hard trial (mean, 95% CI)"),
        Line2D([], [], marker="o", ms=3.5, color="0.5", ls=":", markeredgecolor="black",
               label="model fit"),
    ]
    axes[-1].set_xlabel("trial")
    axes[-1].legend(handles=handles, fontsize=8, loc="upper center", ncol=3, frameon=False,
                    bbox_to_anchor=(0.5, -0.28))
    title = "Mean z-scored responses per trial and fitted model"
    return _finish(fig, title, datasets, out_dir, stem)


def plot_model_correlations(summary: pd.DataFrame, out_dir: str | Path,
                            stem: str = "fig4_model_correlations") -> list[Path]:
    """Figure 4 analog: per dataset, each model's correlation r of the full-sample
    fit (filled circle; the bootstrap median without r) with its 95% bootstrap
    interval centred on it (r_low, r_high of `summarize_bootstrap`). The paper
    drew the percentile interval, which can miss r (docs/results.md).

    `summary` has columns dataset, model, r_median, r_low, r_high and optionally r.
    Returns the PNG and PDF paths.
    """
    datasets = ordered_datasets(summary["dataset"].unique())
    models = _models_in(summary)
    fig = Figure(figsize=(2.4 * len(datasets) * min(max(1.0, len(models) / 4), 1.8) + 3.0,
                          max(4.2, 0.2 * len(models) + 1.4)), layout="constrained")  # room for every legend entry
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    spread = 0.22 if len(models) <= 3 else 0.4
    offsets = np.linspace(-spread, spread, len(models)) if len(models) > 1 else np.zeros(1)
    for off, model in zip(offsets, models):
        s = summary[summary["model"] == model].set_index("dataset").reindex(datasets)
        xs = np.arange(len(datasets)) + off
        med = s["r" if "r" in s else "r_median"].to_numpy()
        err = np.clip(np.vstack([med - s["r_low"].to_numpy(), s["r_high"].to_numpy() - med]), 0, None)
        spec = ModelSpec.parse(model)  # a build-risk measure's risk-only model: squares beside its full model's circles
        ax.errorbar(xs, med, yerr=err, fmt="s" if spec.risk and spec.base == "risk" else "o",
                    ms=8 if len(models) <= 3 else 5, capsize=3, color=model_colour(model), label=model_label(model))
    ax.axhline(0, color="0.85", lw=0.8, zorder=0)
    ax.set_xticks(np.arange(len(datasets)), [dataset_label(d) for d in datasets], fontsize=9)
    ax.set_ylabel("correlation with mean z-scores (r)")
    ax.set_xlim(-0.6, len(datasets) - 0.4)
    ax.set_ylim(min(0.0, float(np.nanmin(summary["r_low"])) - 0.05), 1.02)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
    n_boot = int(summary["n_boot"].iloc[0]) if "n_boot" in summary else 0
    point = "r of the fit" if "r" in summary else "median r"
    title = f"Model correlations: {point} and its 95% interval over {n_boot} bootstrap resamples, centred on it"
    return _finish(fig, title, datasets, out_dir, stem)


def plot_sigma_profile(profile: pd.DataFrame, out_dir: str | Path,
                       choice: pd.DataFrame | None = None, stem: str = "sigma_profile") -> list[Path]:
    """RMSE of the full model against sigma, one line per dataset and their mean
    (dashed), with the pooled choice (`choose_sigma`) marked. Returns PNG and PDF
    paths."""
    datasets = ordered_datasets(profile["dataset"].unique())
    fig = Figure(figsize=(6.5, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for dataset in datasets:
        g = profile[profile["dataset"] == dataset].sort_values("sigma")
        ax.plot(g["sigma"], g["rmse"], "o-", ms=4, label=dataset_label(dataset))
    mean = profile.groupby("sigma")["rmse"].mean().sort_index()
    ax.plot(mean.index, mean.to_numpy(), "k--", lw=1.5, label="mean over datasets")
    if choice is not None:
        pooled = choice[choice["dataset"] == "pooled"]
        if len(pooled):
            s = float(pooled["sigma"].iloc[0])
            # Named in the legend, not written on the axes, so no label covers a point.
            ax.axvline(s, color="0.4", lw=1, ls=":", label=f"chosen sigma = {s:g} d")
    ax.set_xlabel("sigma (units of block length d)")
    ax.set_ylabel("RMSE of Eq. 1 fit (z units)")
    ax.legend(fontsize=8, frameon=False, loc="best")
    return _finish(fig, "Full-model fit error against risk noise sigma", datasets, out_dir, stem)


def plot_effort_risk(effort_by_trial, risk_table: pd.DataFrame, sigma: float,
                     out_dir: str | Path,
                     betas: Sequence[float] | Mapping[str, Sequence[float]] | None = None,
                     stem: str = "effort_risk_pairs", names: Mapping[int, str] | None = None) -> list[Path]:
    """Per-pair effort, risk and full-model cost, easy (red) against hard (blue).

    Works without human data. `effort_by_trial` is anything `effort_per_trial`
    accepts (a trial/sample/effort table is averaged over samples);
    `risk_table` has columns trial, sigma, risk and is read at `sigma`.
    `betas`, one (b0, b1, b2) or {name: (b0, b1, b2)} (e.g. fitted per dataset),
    adds one panel of Eq. 1 cost per entry. Each panel's title counts the pairs
    whose easy trial is strictly lower. A pair the paper's participants judged alike
    (PAPER_NO_DIFFERENCE: pair 11) is hatched blue, an expected tie; any other pair whose
    easy trial is not lower is shaded red: there the quantity disagrees with the paper's
    participants, who found H harder. `names` (pair ->
    its dimension, e.g. "line vs. tower") label the x axis. Returns the PNG and PDF paths.
    """
    E = effort_per_trial(effort_by_trial)
    R = risk_at_sigma(risk_table, sigma)
    panels = [("physical effort E", "E (J s)", E),
              (f"physical risk R at sigma = {sigma:g} d", "R (fraction\nof runs that fall)", R)]
    if betas is not None:
        named = betas if isinstance(betas, Mapping) else {"": betas}
        order = ordered_datasets(named) if isinstance(betas, Mapping) else [""]  # the paper's order in every figure
        for name, b in ((n, named[n]) for n in order):
            label = f", {dataset_label(name)} fit" if name else ""
            b_text = ", ".join(f"{v:.3g}" for v in b)
            panels.append((f"Eq. 1 cost{label}, b = ({b_text})", "predicted\nresponse (z)", full_model_cost(E, R, b)))
    fig = Figure(figsize=(9, 2.5 * len(panels) + 0.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(panels), 1, squeeze=False, sharex=True)[:, 0]
    pairs = np.array(pair_numbers(), dtype=float)
    for ax, (label, ylabel, values) in zip(axes, panels):
        table = pair_table(values)
        for k, row in table.iterrows():
            if int(row["pair"]) in PAPER_NO_DIFFERENCE:  # humans saw no difference: a tie is expected
                ax.axvspan(row["pair"] - 0.45, row["pair"] + 0.45, facecolor="#e3eefa", edgecolor="#7fa7d6",
                           hatch="///", lw=0, zorder=0)
            elif not row["E_lt_H"]:  # reversed or tied (analysis.pairs.TIE_REL): disagrees with the paper
                ax.axvspan(row["pair"] - 0.45, row["pair"] + 0.45, color="#f7d4d0", zorder=0)
            ax.plot([row["pair"] - 0.15, row["pair"] + 0.15], [row["cost_E"], row["cost_H"]],
                    "-", color="0.5", lw=1, zorder=1)
        ax.plot(pairs - 0.15, table["cost_E"], "o", color=EASY_COLOUR, label="easy (E)", zorder=2)
        ax.plot(pairs + 0.15, table["cost_H"], "o", color=HARD_COLOUR, label="hard (H)", zorder=2)
        n_ok = int(table["E_lt_H"].sum())
        notes = []
        for order, word in (("tie", "tied"), ("H<E", "reversed")):
            found = table.loc[table["order"] == order, "pair"].tolist()
            if found:
                notes.append(f"{word}: {', '.join(map(str, found))}")
        rest = f"; {'; '.join(notes)}" if notes else ""
        ax.set_title(f"{label}: E < H in {n_ok}/{len(pair_numbers())} pairs{rest}", fontsize=9)
        ax.set_ylabel(ylabel, fontsize=9)
    from matplotlib.patches import Patch

    handles, _ = axes[0].get_legend_handles_labels()
    handles += [Patch(facecolor="#f7d4d0", label="E not lower than H here, though the paper's participants found H harder"),
                Patch(facecolor="#e3eefa", edgecolor="#7fa7d6", hatch="///",
                      label=f"pair {', '.join(map(str, sorted(PAPER_NO_DIFFERENCE)))}: the paper's participants saw no "
                            "difference (a tie is expected)")]
    fig.legend(handles=handles, fontsize=7.5, frameon=False, loc="outside lower center", ncols=2)
    import textwrap

    labels = [f"{p}\n" + "\n".join(textwrap.wrap(str(names[p]), 11)) if names and p in names else str(p) for p in pair_numbers()]
    axes[-1].set_xticks(pairs, labels, fontsize=6.5 if names else None)
    axes[-1].set_xlabel(f"pair (tie: |H - E| <= {TIE_REL:g} x max(E, H))")
    from_fits = list(betas) if isinstance(betas, Mapping) else []
    return _finish(fig, "Model quantities per easy/hard pair", from_fits, out_dir, stem)


def plot_participant_sigma(table: pd.DataFrame, out_dir: str | Path,
                           stem: str = "participant_sigma") -> list[Path]:
    """Per dataset: a histogram of participants' sigmas (identified ones filled,
    ones whose interval is the whole range hatched) above their profile-likelihood
    intervals, sorted. `table` from `analysis.fit_participant_sigma`."""
    datasets = ordered_datasets(table["dataset"].unique())
    fig = Figure(figsize=(max(5.5, 3.6 * len(datasets)), 5.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, len(datasets), squeeze=False, sharex=True, gridspec_kw={"height_ratios": [1, 1.3]})
    lo, hi = float(table["sigma_low"].min()), float(table["sigma_high"].max())
    bins = np.linspace(lo, hi, 11) if hi > lo else 10
    for k, dataset in enumerate(datasets):
        g = table[table["dataset"] == dataset]
        ident = g[g["identified"]]
        ax = axes[0, k]
        ax.hist([ident["sigma"], g.loc[~g["identified"], "sigma"]], bins=bins, stacked=True,
                color=["tab:blue", "white"], edgecolor="tab:blue", hatch=None,
                label=["interval inside the range", "interval = whole range"])
        ax.set_title(f"{dataset_label(dataset)} (n = {len(g)})", fontsize=9)
        ax.set_ylabel("participants")
        if k == 0:
            ax.legend(fontsize=7, frameon=False)
        ax = axes[1, k]
        g = g.sort_values(["sigma", "sigma_low"]).reset_index(drop=True)
        ax.hlines(np.arange(len(g)), g["sigma_low"], g["sigma_high"], color="0.5", lw=1)
        ax.plot(g["sigma"], np.arange(len(g)), "o", ms=3, color="tab:blue")
        ax.set_xlabel("sigma (units of d)")
        ax.set_ylabel(f"participant (sorted), {int(100 * g['level'].iloc[0])}% interval")
    return _finish(fig, "Each participant's sigma, Eq. 1 (profile-likelihood intervals)", datasets,
                   out_dir, stem)


def _trial_x() -> np.ndarray:
    """x positions of the 24 trials: E and H of a pair 1 apart, pairs 2.6 apart."""
    return np.array([2.6 * (int(t[:-1]) - 1) + (t[-1] == "H") for t in trial_ids()], dtype=float)


def _fit_title(fig: Figure, title: str, **style) -> None:
    """Set the figure title, wrapping each line until it fits the figure's width."""
    import textwrap

    lines = title.split("\n")
    width = max(len(line) for line in lines)
    while True:
        text = "\n".join(textwrap.fill(line, width) for line in lines)
        artist = fig.suptitle(text, **style)
        box = artist.get_window_extent(fig.canvas.get_renderer())
        if box.width <= 0.96 * fig.bbox.width or width <= 20:
            return
        width = max(20, int(width * 0.96 * fig.bbox.width / box.width) - 1)


def _finish(fig: Figure, title: str, datasets: Iterable[str], out_dir: str | Path,
            stem: str) -> list[Path]:
    """Label simulated figures, save PNG and PDF, return their paths."""
    simulated = any(is_simulated_dataset(d) for d in datasets)
    if simulated:
        title = f"{SIMULATED_TITLE}\n{title}"
        if "simulated" not in stem:
            stem = f"simulated_{stem}"
    # Constrained layout (set when the figure was made) keeps the title above the
    # panels; _fit_title wraps it to the figure's width. Tests check its bounding box.
    _fit_title(fig, title, fontsize=11, color="darkred" if simulated else "black")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.png", out_dir / f"{stem}.pdf"]
    # The title is also stored as file metadata, so a reader (or a test) can check
    # the simulated label without looking at pixels.
    flat_title = title.replace("\n", ": ")
    with atomic_path(paths[0]) as tmp:
        fig.savefig(tmp, dpi=150, metadata={"Title": flat_title})
    # The PDF keeps the layout the PNG's draw solved (axes within 0.2 pt of solving it
    # again for the PDF's renderer, measured): solving it again was a third of the figure's time.
    fig.set_layout_engine("none")
    with atomic_path(paths[1]) as tmp:
        fig.savefig(tmp, metadata={"Title": flat_title})
    return paths


SCHEME_STYLE = {"in-sample": ("in-sample (fit and scored on all 24 trials)", 0.35, ""),
                "leave-one-pair-out": ("out of sample: leave-one-pair-out", 1.0, ""),
                "leave-one-trial-out": ("out of sample: leave-one-trial-out", 0.7, "//"),
                "leave-one-structure-out": ("out of sample: folds by structure (identical B held out together)", 0.85,
                                            "..")}


def plot_model_comparison(summary: pd.DataFrame, out_dir: str | Path, stem: str = "fig4_model_comparison",
                          gain: pd.DataFrame | None = None) -> list[Path]:
    """Figure 4 analog with in-sample and out-of-sample bars: per dataset and
    model, the correlation of the model with the trial means in sample (pale)
    and of its held-out predictions (full colour; hatched leave-one-trial-out),
    with the bootstrap 95% intervals (`analysis.crossval.summarize_comparison`).
    With `gain` (`gain_over_effort`) a second panel shows how much lower each
    model's RMSE is than effort-only's under each scheme: in sample Eq. 1's gain
    cannot be negative, out of sample it can. Returns the PNG and PDF paths."""
    from matplotlib.patches import Patch

    datasets = ordered_datasets(summary["dataset"].unique())
    models = _models_in(summary)
    schemes = [s for s in SCHEME_STYLE if s in set(summary["scheme"])]
    panels = 2 if gain is not None else 1
    wide = min(max(1.0, len(models) * len(schemes) / 9), 2.0)
    fig = Figure(figsize=(2.9 * len(datasets) * wide + 2.6, 4.2 * panels + 0.4), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(panels, 1, squeeze=False)[:, 0]

    def bars(ax, table, value, low, high, models_here):
        # One bar call and one errorbar call per (model, scheme), over the datasets
        # (the first row of each): the same bars as one call per bar, a tenth of the artists.
        width = 0.8 / (len(models_here) * len(schemes))
        first = table.drop_duplicates(["dataset", "model", "scheme"]).set_index(["model", "scheme", "dataset"]).sort_index()
        for j, model in enumerate(models_here):
            for k, scheme in enumerate(schemes):
                if (model, scheme) not in first.index.droplevel("dataset"):
                    continue
                rows = first.loc[(model, scheme)].reindex(datasets)
                shown = rows[value].notna().to_numpy()
                if not shown.any():
                    continue
                rows = rows[shown]
                x = np.flatnonzero(shown) - 0.4 + width * (j * len(schemes) + k + 0.5)
                y = rows[value].to_numpy(float)
                _, alpha, hatch = SCHEME_STYLE[scheme]
                ax.bar(x, y, width * 0.92, color=model_colour(model), alpha=alpha, hatch=hatch,
                       edgecolor="white" if hatch else model_colour(model), lw=0.5)
                if low in rows:
                    lo_, hi_ = rows[low].to_numpy(float), rows[high].to_numpy(float)
                    ok = np.isfinite(lo_)
                    if ok.any():
                        ax.errorbar(x[ok], y[ok], yerr=[np.fmax(0.0, y[ok] - lo_[ok]), np.fmax(0.0, hi_[ok] - y[ok])],
                                    fmt="none", ecolor="0.25", elinewidth=1, capsize=2)
        ax.axhline(0, color="0.6", lw=0.8)
        ax.set_xticks(np.arange(len(datasets)), [dataset_label(d) for d in datasets], fontsize=9)
        ax.set_xlim(-0.5, len(datasets) - 0.5)
        handles = [Patch(color=model_colour(m), label=model_label(m)) for m in models_here]
        handles += [Patch(facecolor="0.3", alpha=SCHEME_STYLE[s][1], hatch=SCHEME_STYLE[s][2], edgecolor="white",
                          label=SCHEME_STYLE[s][0]) for s in schemes]
        ax.legend(handles=handles, fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)

    ax = axes[0]
    bars(ax, summary, "r", "r_low", "r_high", models)
    ax.set_ylabel("correlation with mean z-scores (r)")
    low = np.nanmin(summary["r_low"]) if "r_low" in summary else np.nanmin(summary["r"])
    ax.set_ylim(min(0.0, float(low) - 0.05), 1.02)
    ax.set_title("r of each model: fit and scored on all trials (pale) or predicting held-out trials", fontsize=9)
    if gain is not None:
        ax = axes[1]
        # Eq. 1 and its two no-physics competitors with as many parameters (risk-only's losses dwarf the scale)
        bars(ax, gain, "gain", "gain_low", "gain_high",
             [m for m in ("full", "effort+height", "effort+stacked") if m in set(gain["model"])])
        ax.set_ylabel("RMSE of effort-only minus\nthe model's (z units)")
        ax.set_title("Gain over effort-only (Eq. 1 and effort + a heuristic): above 0 it predicts better.\nIn sample it "
                     "cannot fall below 0; out of sample it can. Whiskers: bootstrap interval centred on the gain",
                     fontsize=9)  # two lines: as one, wider than the axes, it ran off the figure's left edge
    n_boot = int(summary["n_boot"].max()) if "n_boot" in summary and summary["n_boot"].notna().any() else 0
    title = ("Models in sample and out of sample (sigma chosen inside each fold); bars: full sample, whiskers: 95% "
             f"interval over {n_boot} bootstrap resamples, centred on the bar")
    return _finish(fig, title, datasets, out_dir, stem)


def plot_recovery(summary: pd.DataFrame, out_dir: str | Path, paper_sigma: float = 0.065,
                  source: str = "stated", stem: str = "simulated_recovery", note: str = "") -> list[Path]:
    """Model recovery on SIMULATED studies (analysis.recovery): left, the share of
    studies whose verdict is the true model against participants, one line per
    true model, out of sample (solid, leave-one-pair-out) and in sample (dotted),
    at the table's sigma nearest `paper_sigma`; right, the share in which Eq. 1
    beats effort-only out of sample against the true sigma, when Eq. 1 is true
    (solid) and when effort-only is (dashed), one colour per participant count."""
    s = summary[summary["source"] == source]
    sigmas = np.sort(s["sigma"].unique())
    sig = float(sigmas[np.argmin(np.abs(sigmas - paper_sigma))])
    fig = Figure(figsize=(11, 4.3), layout="constrained")
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2)
    at = s[np.isclose(s["sigma"], sig)]
    markers = {"full": ("o", 9), "effort": ("s", 7), "risk": ("^", 5)}   # sizes differ so overlapping lines show
    for model in MODELS:
        for proc, ls in (("leave-one-pair-out", "-"), ("in-sample", ":")):
            g = at[(at["true_model"] == model) & (at["procedure"] == proc)].sort_values("participants")
            if len(g):
                marker, ms = markers[model]
                left.plot(g["participants"], g["p_right"], ls, marker=marker, ms=ms, color=model_colour(model),
                          label=f"true: {model_label(model)}" + ("" if ls == "-" else " (in-sample)"))
    left.set_xscale("log")
    ns = sorted(at["participants"].unique())
    left.set_xticks(ns, [str(n) for n in ns])
    left.set_xticks([], minor=True)
    left.set_ylim(-0.03, 1.03)
    left.axhline(1 / 3, color="0.8", lw=0.8, ls="--")
    left.set_xlabel("participants per study")
    left.set_ylabel("share of studies: verdict = true model")
    left.set_title(f"Right verdict at sigma = {sig:g} d (solid: leave-one-pair-out; dotted: in-sample)", fontsize=9)
    left.legend(fontsize=7, frameon=False, loc="lower right")
    lo = s[s["procedure"] == "leave-one-pair-out"]
    colours = ["tab:purple", "tab:blue", "tab:cyan", "tab:olive", "tab:brown"]
    for n, colour in zip(sorted(lo["participants"].unique()), colours * 3):
        for model, ls in (("full", "-"), ("effort", "--")):
            g = lo[(lo["participants"] == n) & (lo["true_model"] == model)].sort_values("sigma")
            right.plot(g["sigma"], g["p_full_beats_effort"], ls, marker="o", ms=3, color=colour,
                       label=f"n = {n}, true: {'Eq. 1' if model == 'full' else 'effort only'}")
    right.axvline(paper_sigma, color="0.6", lw=0.8, ls=":")
    right.set_ylim(-0.03, 1.03)
    right.set_xlabel("true sigma (units of d)")
    right.set_ylabel("share of studies: Eq. 1 beats effort-only")
    right.set_title("Eq. 1 vs effort-only out of sample (leave-one-pair-out)", fontsize=9)
    right.legend(fontsize=7, frameon=False, loc="best")
    title = f"Model recovery on our effort and risk tables{f' ({note})' if note else ''}"
    return _finish(fig, title, ["simulated-recovery"], out_dir, stem)

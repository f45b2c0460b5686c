"""The renderer of the build-risk stage (lgp/app/build_risk.py): its tables
(build_risk_stages.csv, build_risk.csv, build_risk_pairs.csv), the figure of risk
by stage, the report section, and its per-trial tables on the page's trial cards.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.build_risk import SEQUENTIAL_SAMPLES, BuildRisk
from lgp.app.files import atomic_path, write_csv_atomic
from lgp.app.result import Rendered
from lgp.paper import PAIRS

EASY, HARD = "tab:red", "tab:blue"


def pair_markdown(pairs: pd.DataFrame, sigma: float) -> str:
    """One row per pair, one column per measure, cells 'E / H' (a * where E < H)."""
    from models.risk.build import MEASURES

    g = pairs[np.isclose(pairs["sigma"], sigma)]
    lines = ["| pair | " + " | ".join(f"{m} E / H" for m in MEASURES) + " |", "|---|" + "---|" * len(MEASURES)]
    for pair, p in g.groupby("pair", sort=True):
        p = p.set_index("measure")
        cells = [f"{p.at[m, 'E']:.3f} / {p.at[m, 'H']:.3f}{' *' if p.at[m, 'E_lt_H'] else ''}" for m in MEASURES]
        lines.append(f"| {pair} | " + " | ".join(cells) + " |")
    counts = g.groupby("measure", sort=False)["E_lt_H"].sum()
    lines.append("| pairs E < H | " + " | ".join(f"{int(counts[m])} of {g['pair'].nunique()}" for m in MEASURES) + " |")
    return "\n".join(lines)


def plot_stage_curves(stages: pd.DataFrame, out_dir: str | Path, stem: str = "build_risk_stages") -> list[Path]:
    """Risk by stage, mean over layouts: one panel per pair, E (red) and H (blue),
    solid at the first sigma, dashed at the others. PNG and PDF paths."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    from models.risk.build import stage_curve

    curve = stage_curve(stages)
    sigmas = sorted(curve["sigma"].unique())
    fig = Figure(figsize=(12, 8.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 4, sharey=True).ravel()
    for ax, pair in zip(axes, PAIRS):
        for level, colour in (("E", EASY), ("H", HARD)):
            for k, sigma in enumerate(sigmas):
                c = curve[(curve["trial"] == f"{pair}{level}") & np.isclose(curve["sigma"], sigma)]
                if len(c):
                    ax.plot(c["stage"], c["risk"], "o-" if k == 0 else "s--", ms=3, color=colour, lw=1.2,
                            label=f"{pair}{level}, sigma {sigma:g} d")
        ax.set_title(f"pair {pair}", fontsize=9)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("stage (after the k-th Place)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, frameon=False, loc="upper left")
    for ax in axes[::4]:
        ax.set_ylabel("risk (mean over layouts)", fontsize=8)
    fig.suptitle("Risk through the build: each stage's fraction of noisy runs that fall", fontsize=11)
    fig.tight_layout()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.png", out_dir / f"{stem}.pdf"]
    for p in paths:
        with atomic_path(p) as tmp:
            fig.savefig(tmp, dpi=130)
    return paths


def write_outputs(data: BuildRisk, out: Path) -> tuple[list[Path], str]:
    """Write the stage table, aggregates, pair table and figure; return the paths and
    the report section (markdown)."""
    from models.risk.build import MEASURES

    aggregates = data.aggregates
    written = [write_csv_atomic(data.stages, out / "build_risk_stages.csv"),
               write_csv_atomic(aggregates, out / "build_risk.csv")]
    lines = ["## Risk through the build (beyond the paper)", "",
             f"Command: `{data.command}`. Stages are the states after each Place of the plan of every layout "
             "(models/risk/build.py); aggregates per plan, averaged over layouts: final = r_K, max = max r_k, "
             "expected = sum r_k, any = 1 - prod(1 - r_k) (as if the stages were independent, which they are not: "
             "they share their random numbers), care = sum w_k r_k (w_k: share of the plan's effort "
             "already spent on the structure, a squared-carry-distance proxy checked against KOMO); "
             "sequential = the fraction of runs of one noisy build, carried stage to stage from settled poses, that "
             f"collapse at some stage (mode=\"sequential\", on the plan of the first {SEQUENTIAL_SAMPLES} layout(s)), "
             "last_stage = the fraction of the runs reaching the last stage that collapse there (next to final, "
             "the paper's R).", ""]
    shown = [*MEASURES, "last_stage"]
    lines += ["| trial | sigma | " + " | ".join(shown) + " | stages |", "|---|---|" + "---|" * (len(shown) + 1)]
    for _, r in aggregates.iterrows():
        lines.append(f"| {r['trial']} | {r['sigma']:g} | " + " | ".join(f"{r[m]:.3f}" for m in shown)
                     + f" | {r['stages']:g} |")
    lines.append("")
    if data.pairs is not None:
        written.append(write_csv_atomic(data.pairs, out / "build_risk_pairs.csv"))
        for sigma in sorted(aggregates["sigma"].unique()):
            lines += [f"### sigma = {sigma:g} d (cells E / H; * where E < H)", "", pair_markdown(data.pairs, sigma), ""]
        written += plot_stage_curves(data.stages, out / "figures")
    else:
        lines += ["A subset of trials: no pair table or figure (they need all 24).", ""]
    return written, "\n".join(lines)


def render(data: BuildRisk, view) -> Rendered:
    """The stage's files and report section; the trial cards show its stage table and aggregates."""
    files, report = write_outputs(data, view.out)
    return Rendered(files, report, card_tables={"build_risk": data.aggregates, "build_risk_stages": data.stages})


def build_risk_outputs(stages: pd.DataFrame, out: Path, command: str) -> tuple[list[Path], str, pd.DataFrame]:
    """The outputs of a stage table written into `out`: (paths, report section, long measure table)."""
    data = BuildRisk.of(stages, command)
    paths, section = write_outputs(data, out)
    return paths, section, data.measures_of(data.aggregates["trial"].unique())

"""The build-risk stage of `python -m lgp.reproduce --build-risk`: risk
through the build (models/risk/build.py) of every trial, cached per trial, its
aggregates, the pair table of aggregates, the small-multiples figure of risk by
stage and a report section.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.cache import Cache, input_key
from lgp.app.files import atomic_path, write_csv_atomic
from lgp.app.progress import log as _log
from lgp.paper import PAIRS, PAPER_SIGMA

#: The noise levels the build-risk report uses: the paper's sigma, 0.065 d, and 0.10 d.
BUILD_SIGMAS: tuple[float, ...] = (PAPER_SIGMA, 0.1)
#: Layouts whose plan the sequential build (mode="sequential") is run on: one,
#: sample 0 (a tower's plan is the same for every layout; a sequential build of
#: 30 layouts of a floor is 30 builds of 15 stages per run).
SEQUENTIAL_SAMPLES = 1
EASY, HARD = "tab:red", "tab:blue"


def build_key_inputs(model) -> dict:
    """What a stage table depends on besides the trial and the parameters: the
    RiskModel `model` as the tables record it and lgp.app.stages.engine_key_inputs
    of models.risk.build (its code, the engine's settings, the libraries and the
    engine's own, e.g. sapien for PhysX)."""
    from lgp.app.stages import engine_key_inputs
    from models.risk import RiskModel

    model = RiskModel.of(model)
    return {**model.record(), **engine_key_inputs(model.engine, "models.risk.build")}


def build_risk_tables(trials, sigmas, n_sims: int, samples: int, seed: int, model, executor, cache: Cache, *,
                      approach_height: float | None = None,
                      sequential_samples: int = SEQUENTIAL_SAMPLES, verbose: bool = False) -> pd.DataFrame:
    """The stage table of every trial (models.risk.build_risk) under the RiskModel
    `model`, one cached file per trial and mode keyed by the trial file, the
    parameters and the code it depends on: mode "stages" over `samples` layouts
    and mode "sequential" over the first `sequential_samples` (the `sequential`
    aggregate). `approach_height`: the effort run's (work shares only). Ends with
    one line; `verbose` also prints a line per trial (its risks, labelled by sigma)."""
    from models.risk import RiskModel
    from models.risk.build import build_risk

    model = RiskModel.of(model)
    depends = {**build_key_inputs(model), "approach_height": approach_height}
    out = []
    computed = 0
    for k, trial in enumerate(trials, 1):
        t0 = time.perf_counter()
        hows, tables = [], []
        for mode, m in (("stages", samples), ("sequential", min(samples, sequential_samples))):
            key = input_key(trial=trial.id, digest=trial.digest, sigmas=[float(s) for s in sigmas], n_sims=n_sims,
                            samples=m, seed=seed, mode=mode, **depends)
            df = cache.get("buildrisk", key)
            how = "cached"
            if df is None:
                t1 = time.perf_counter()
                df = cache.put("buildrisk", key, build_risk(trial, list(sigmas), n_sims=n_sims, samples=m, seed=seed,
                                                            model=model, executor=executor, mode=mode,
                                                            approach_height=approach_height))
                how = f"{time.perf_counter() - t1:.1f} s"
                computed += 1
            hows.append(f"{mode} {how}")
            tables.append(df)
        df, seq = tables
        if verbose:
            final = df[df["stage"] == df.groupby("sample")["stage"].transform("max")]
            at = ", ".join(f"{s:g}" for s in sorted(final["sigma"].unique()))
            curve = ", ".join(f"{r:.2f}" for r in final.groupby("sigma")["risk"].mean())
            collapsed = ", ".join(f"{r:.2f}" for r in seq.groupby("sigma")["risk"].sum() / seq.groupby("sigma")["sample"].nunique())
            _log(f"[build  {k:2d}/{len(trials)}] {trial.id:>3}: {df['stage'].max()} stages; at sigma {at} d: "
                 f"risk of the finished stage {curve}; sequential build collapses {collapsed} ({', '.join(hows)})")
        out += tables
    n = 2 * len(trials)
    _log(f"build risk: {len(trials)} trial(s) at sigma {', '.join(f'{s:g}' for s in sigmas)} d; {computed} of {n} tables "
         f"computed, {n - computed} reused from this folder's cache" + ("" if verbose else " (--verbose: a line per trial)"))
    return pd.concat(out, ignore_index=True)


def aggregate_pairs(aggregates: pd.DataFrame) -> pd.DataFrame:
    """Per (sigma, pair, measure): the aggregate of E and of H and whether E < H
    under the one tie rule (analysis.pairs.pair_order: a difference within TIE_REL
    is a tie, not an order, so two equal aggregates a rounding apart stay tied)."""
    from analysis.pairs import pair_order
    from models.risk.build import MEASURES

    rows = []
    for sigma, g in aggregates.groupby("sigma", sort=True):
        by = g.set_index("trial")
        for pair in PAIRS:
            e, h = f"{pair}E", f"{pair}H"
            if e not in by.index or h not in by.index:
                continue
            for m in MEASURES:
                rows.append((sigma, pair, m, by.at[e, m], by.at[h, m], pair_order(by.at[e, m], by.at[h, m]) == "E<H"))
    return pd.DataFrame(rows, columns=["sigma", "pair", "measure", "E", "H", "E_lt_H"])


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


def build_risk_outputs(stages: pd.DataFrame, out: Path, command: str) -> tuple[list[Path], str, pd.DataFrame]:
    """Write the stage table, aggregates, pair table and figure; return the paths,
    the report section (markdown) and the long measure table for the analysis."""
    from models.risk.build import build_risk_aggregates, measure_table

    aggregates = build_risk_aggregates(stages)
    written = [write_csv_atomic(stages, out / "build_risk_stages.csv"),
               write_csv_atomic(aggregates, out / "build_risk.csv")]
    lines = ["## Risk through the build (beyond the paper)", "",
             f"Command: `{command}`. Stages are the states after each Place of the plan of every layout "
             "(models/risk/build.py); aggregates per plan, averaged over layouts: final = r_K, max = max r_k, "
             "expected = sum r_k, any = 1 - prod(1 - r_k) (as if the stages were independent, which they are not: "
             "they share their random numbers), care = sum w_k r_k (w_k: share of the plan's effort "
             "already spent on the structure, a squared-carry-distance proxy checked against KOMO); "
             "sequential = the fraction of runs of one noisy build, carried stage to stage from settled poses, that "
             f"collapse at some stage (mode=\"sequential\", on the plan of the first {SEQUENTIAL_SAMPLES} layout(s)), "
             "last_stage = the fraction of the runs reaching the last stage that collapse there (next to final, "
             "the paper's R).", ""]
    from models.risk.build import MEASURES

    shown = [*MEASURES, "last_stage"]
    lines += ["| trial | sigma | " + " | ".join(shown) + " | stages |", "|---|---|" + "---|" * (len(shown) + 1)]
    for _, r in aggregates.iterrows():
        lines.append(f"| {r['trial']} | {r['sigma']:g} | " + " | ".join(f"{r[m]:.3f}" for m in shown)
                     + f" | {r['stages']:g} |")
    lines.append("")
    complete = set(aggregates["trial"]) >= {f"{p}{lv}" for p in PAIRS for lv in "EH"}
    if complete:
        pairs = aggregate_pairs(aggregates)
        written.append(write_csv_atomic(pairs, out / "build_risk_pairs.csv"))
        for sigma in sorted(aggregates["sigma"].unique()):
            lines += [f"### sigma = {sigma:g} d (cells E / H; * where E < H)", "", pair_markdown(pairs, sigma), ""]
        written += plot_stage_curves(stages, out / "figures")
    else:
        lines += ["A subset of trials: no pair table or figure (they need all 24).", ""]
    return written, "\n".join(lines), measure_table(aggregates)

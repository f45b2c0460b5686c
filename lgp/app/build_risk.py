"""The build-risk stage of `python -m lgp.reproduce --build-risk`: risk
through the build (models/risk/build.py) of every trial, cached per trial, its
aggregates and the pair table of aggregates, as data (`BuildRisk`). Its renderer,
lgp/app/build_risk_view.py, writes the tables, the figure and the report section.
This file and that one are the whole feature (with its settings in RunConfig).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import pandas as pd

from lgp.app.cache import Cache, input_key
from lgp.app.progress import log as _log
from lgp.paper import PAIRS, PAPER_SIGMA, TRIAL_IDS

#: The noise levels the build-risk report uses: the paper's sigma, 0.065 d, and 0.10 d.
BUILD_SIGMAS: tuple[float, ...] = (PAPER_SIGMA, 0.1)
#: Layouts whose plan the sequential build (mode="sequential") is run on: one,
#: sample 0 (a tower's plan is the same for every layout; a sequential build of
#: 30 layouts of a floor is 30 builds of 15 stages per run).
SEQUENTIAL_SAMPLES = 1


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




@dataclass(frozen=True)
class BuildRisk:
    """Risk through the build: the stage table (models.risk.build.build_risk of every
    trial), its aggregates per (trial, sigma), the pair table of the aggregates (None
    on a subset of the paper's trials) and the command that made them."""

    stages: pd.DataFrame
    aggregates: pd.DataFrame
    pairs: pd.DataFrame | None
    command: str

    @classmethod
    def of(cls, stages: pd.DataFrame, command: str) -> "BuildRisk":
        from models.risk.build import build_risk_aggregates

        aggregates = build_risk_aggregates(stages)
        complete = set(aggregates["trial"]) >= set(TRIAL_IDS)
        return cls(stages, aggregates, aggregate_pairs(aggregates) if complete else None, command)

    def measures_of(self, trials) -> pd.DataFrame:
        """The long measure table (trial, sigma, measure, risk) of `trials`, what the analysis fits."""
        from models.risk.build import measure_table

        long = measure_table(self.aggregates)
        return long[long["trial"].isin(trials)]


def add_arguments(parser, cli) -> None:
    """The stage's command-line options."""
    parser.add_argument("--build-risk", action="store_true", help="also risk through the build, at --build-sigmas (lgp/app/build_risk.py)")
    parser.add_argument("--build-sigmas", type=cli.sigma, nargs="+",
                        help=f"noise levels of --build-risk in (0, 1] (default {' '.join(f'{s:g}' for s in BUILD_SIGMAS)})")


class _Stage:
    name, phase = "build_risk", "compute"

    def enabled(self, config) -> bool:
        return config.build_risk

    def run(self, ctx) -> BuildRisk:
        c = ctx.config
        stages = build_risk_tables(ctx.trials, c.build_sigmas or BUILD_SIGMAS, c.n_sims, c.samples, c.seed, c.risk_model,
                                   ctx.executor, ctx.cache, approach_height=c.approach_height, verbose=c.verbose)
        return BuildRisk.of(stages, c.command)


STAGE = _Stage()


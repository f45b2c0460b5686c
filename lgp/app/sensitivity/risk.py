"""The risk section of --sensitivity (`risk_section`): the risk of every trial at the paper's
sigma and at 0.10 d, for each installed engine (mujoco; drake when asked with
--sensitivity-engines or --engine drake; physx faithful; physx game-defaults,
UNFAITHFUL) x fall rule (horizontal 0.25 d, 3-D 0.25 d, 3-D 0.1 d) x noise rule
(lift, the default, and settle: models/risk/noise.py): how many
trials have risk > 0 and which of the paper's four risk contrasts (4H > 4E, 5H >
5E, 7H > 7E, 8H > 8E) come out. Nothing is fitted or tuned here; every engine
runs with its own fixed settings (docs/risk.md). Writes risk_sensitivity.csv
(tidy: one row per engine, rule, trial, sigma), risk_sensitivity_summary.csv and
figures/risk_sensitivity.png (one panel per engine and rule).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.cache import input_key
from lgp.app.files import atomic_path
from lgp.app.sensitivity.section import Context, Section, markdown
from lgp.paper import BLOCK_SIZE, PAPER_SIGMA, RISK_PAIRS
from models.risk.model import DEFAULT_MODEL, FALL_COLUMNS, FALL_THRESHOLD, MODEL_COLUMNS, NOISE_RULES, FallRule, RiskModel

#: The noise levels of the risk section: the paper's sigma and the top of its grid.
RISK_SIGMAS = (PAPER_SIGMA, 0.10)
#: Fall rules of the risk section, as models whose fall rule and threshold judge
#: the runs (RiskModel.judged_by). The runs are simulated once per engine and
#: noise rule and judged by each (exact: every threshold here has the same
#: early-stop distance, RiskModel.stop_distance).
RISK_RULES = (DEFAULT_MODEL, RiskModel(None, None, FallRule.THREE_D, FALL_THRESHOLD),
              RiskModel(None, None, FallRule.THREE_D, 0.1))
#: Engines of the risk section when none are named: every installed one but Drake
#: (about 100x slower; add it with --sensitivity-engines ... drake or --engine drake).
DEFAULT_RISK_ENGINES = ("mujoco", "physx", "physx:game-defaults")

COLUMNS = ["engine", "faithful", *MODEL_COLUMNS[1:], "trial", "sigma", "risk", "falls", "n", "stands_unperturbed"]


def risk_engines(args) -> tuple[list[str], list[str]]:
    """(engines to run, notes on engines left out)."""
    from models.risk import ENGINES, EngineUnavailableError, engine_name

    wanted = list(args.sensitivity_engines or DEFAULT_RISK_ENGINES)
    if args.engine == "drake" and "drake" not in wanted:
        wanted.insert(1, "drake")
    names, notes = [], []
    for name in wanted:
        try:
            names.append(engine_name(name))
        except EngineUnavailableError as e:
            notes.append(str(e))
    order = list(ENGINES)
    return sorted(dict.fromkeys(names), key=order.index), notes


def _engine_runs(ctx: Context, model: RiskModel, n_sims: int, seed: int) -> pd.DataFrame:
    """Per-run tables of every trial for one engine and noise rule (`model`, with
    the default fall rule) at RISK_SIGMAS, one cached file per trial; trials whose
    B falls unperturbed are left out (they are flagged by `_stands`)."""
    from models.risk import UnstableSceneError, check_stable, risk_table

    depends = ctx.risk_key(model)  # the runs are judged by every rule of RISK_RULES afterwards
    keys = {t.id: input_key(trial=t.id, digest=t.digest, sigmas=list(RISK_SIGMAS), n_sims=n_sims, seed=seed,
                            table="runs", **depends) for t in ctx.trials}
    tables = {t.id: ctx.cache.get("sensitivity", keys[t.id]) for t in ctx.trials}
    todo = []
    for t in ctx.trials:
        if tables[t.id] is None:
            try:
                check_stable(t.target, model.engine)
                todo.append(t)
            except UnstableSceneError:
                pass
    if todo:
        t0 = time.perf_counter()
        runs = risk_table(todo, list(RISK_SIGMAS), n_sims=n_sims, seed=seed, model=model, runs=True, executor=ctx.executor)
        for t in todo:
            tables[t.id] = ctx.cache.put("sensitivity", keys[t.id], runs[runs["trial"] == t.id].reset_index(drop=True))
        ctx.log(f"[sensitivity] {model.engine}, {model.noise_rule}: {len(runs)} runs of {len(todo)} trials in {time.perf_counter() - t0:.1f} s")
    else:
        ctx.log(f"[sensitivity] {model.engine}, {model.noise_rule}: cached")
    found = [df for df in tables.values() if df is not None]
    return pd.concat(found, ignore_index=True) if found else pd.DataFrame()


def _stands(trial, model: RiskModel) -> bool:
    from models.risk import UnstableSceneError, check_stable

    try:
        check_stable(trial.target, model)
        return True
    except UnstableSceneError:
        return False


def risk_sensitivity_table(ctx: Context, engines: list[str]) -> pd.DataFrame:
    """Tidy table (COLUMNS): risk per engine, rule, trial and sigma."""
    from models.risk import ENGINES, summarise

    rows = []
    for engine, noise_rule in ((e, nr) for e in engines for nr in NOISE_RULES):
        simulated = RiskModel(engine, noise_rule=noise_rule)
        runs = _engine_runs(ctx, simulated, ctx.args.n_sims, ctx.args.seed)
        for judge in RISK_RULES:
            model = simulated.judged_by(judge)
            judged = model.rejudge(runs, BLOCK_SIZE) if len(runs) else runs
            risk = summarise(judged) if len(judged) else pd.DataFrame(columns=["trial", "sigma", "risk", "falls", "n"])
            for t in ctx.trials:
                stands = _stands(t, model)
                for sigma in RISK_SIGMAS:
                    r = risk[(risk["trial"] == t.id) & np.isclose(risk["sigma"], sigma)]
                    base = {**model.record(), "faithful": ENGINES[engine].faithful, "trial": t.id, "sigma": sigma,
                            "stands_unperturbed": stands}
                    if len(r):
                        rows.append({**base, "risk": float(r["risk"].iloc[0]), "falls": int(r["falls"].iloc[0]),
                                     "n": int(r["n"].iloc[0])})
                    else:  # B falls with no noise under this engine: no risk, said so in the table and report
                        rows.append({**base, "risk": np.nan, "falls": 0, "n": 0})
    return pd.DataFrame(rows, columns=COLUMNS)


def risk_sensitivity_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per engine, rule and sigma: trials with risk > 0, each of the paper's risk
    contrasts (H riskier than E, under the one tie rule, analysis.pairs.pair_order)
    and how many of them come out."""
    from analysis.pairs import pair_order
    out = []
    if "noise_rule" not in table:
        table = table.assign(noise_rule="lift")
    keys = ["engine", "faithful", *MODEL_COLUMNS[1:], "sigma"]
    for values, g in table.groupby(keys, sort=False):
        risk = dict(zip(g["trial"], g["risk"]))
        row = {**dict(zip(keys, values)), "faithful": bool(values[1]),
               "trials": int(g["risk"].notna().sum()), "trials_risk_gt_0": int((g["risk"] > 0).sum()),
               "unstable_unperturbed": int((~g["stands_unperturbed"].astype(bool)).sum())}
        for pair in RISK_PAIRS:
            h, e = risk.get(f"{pair}H", np.nan), risk.get(f"{pair}E", np.nan)
            row[f"{pair}H>{pair}E"] = pair_order(e, h) == "E<H" if np.isfinite(h) and np.isfinite(e) else None
        row["contrasts"] = sum(bool(row[f"{p}H>{p}E"]) for p in RISK_PAIRS)
        out.append(row)
    return pd.DataFrame(out)


def risk_sensitivity_figure(table: pd.DataFrame, path: Path) -> Path:
    """Risk of every trial over sigma, one panel per engine and rule (hard trials
    solid, easy dashed; the risk-contrast pairs in colour)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if "noise_rule" not in table:
        table = table.assign(noise_rule="lift")
    panels = list(table.groupby(["engine", "noise_rule", *FALL_COLUMNS], sort=False))
    ncol = len(RISK_RULES)
    nrow = -(-len(panels) // ncol)
    fig = Figure(figsize=(3.6 * ncol, 2.9 * nrow))
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrow, ncol, sharex=True, sharey=True, squeeze=False)
    colours = dict(zip(RISK_PAIRS, ("tab:red", "tab:blue", "tab:green", "tab:purple")))
    for ax, ((engine, noise_rule, rule, thr), g) in zip(axes.flat, panels):
        for trial, c in g.groupby("trial", sort=False):
            pair = int(trial[:-1])
            colour = colours.get(pair, "0.75")
            ax.plot(c["sigma"], c["risk"], ls="-" if trial.endswith("H") else "--", marker="o", ms=3, color=colour,
                    lw=1.4 if pair in colours else 0.8, label=trial if pair in colours else None)
        label = engine + ("" if g["faithful"].iloc[0] else " (UNFAITHFUL)")
        ax.set_title(f"{label}, {noise_rule}\n{rule} > {thr:g} d", fontsize=9)
        ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("sigma (x d)")
    for ax in axes[:, 0]:
        ax.set_ylabel("risk")
    axes.flat[0].legend(fontsize=6, ncol=2, loc="upper left")
    fig.suptitle("Risk by engine, noise rule and fall rule (grey: pairs without a risk contrast)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    return path


def risk_section(ctx: Context) -> Section:
    engines, notes = risk_engines(ctx.args)
    table = risk_sensitivity_table(ctx, engines)
    summary = risk_sensitivity_summary(table)
    shown = summary.assign(engine=[e if f else f"{e} (UNFAITHFUL)" for e, f in zip(summary["engine"], summary["faithful"])],
                           rule=[f"{r} > {t:g} d" for r, t in zip(*(summary[c] for c in FALL_COLUMNS))])
    shown = shown.assign(suite=["passes" if f else "fails (docs/risk.md)" for f in shown["faithful"]])
    cols = ["engine", "suite", "noise_rule", "rule", "sigma", "trials_risk_gt_0", *[f"{p}H>{p}E" for p in RISK_PAIRS],
            "contrasts"]
    if summary["unstable_unperturbed"].any():
        cols.insert(5, "unstable_unperturbed")
    lines = [
        "## Sensitivity of risk to the engine, the noise rule and the fall rule",
        "",
        f"Risk of every trial at sigma = {', '.join(f'{s:g}' for s in RISK_SIGMAS)} d, N = {ctx.args.n_sims} runs, "
        f"seed {ctx.args.seed}, for each engine x noise rule x fall rule (a run falls when a block centre ends more "
        "than the threshold from its start, in the horizontal plane or in 3-D; the noise rule `lift` leaves noisy "
        "blocks up to a few mm above their supports, `settle` sets each onto what lies beneath it). Same perturbed scenes for every engine; "
        "each engine runs with its own fixed settings and nothing was tuned. The faithful engines pass the "
        "faithfulness suite (tests/test_risk_engines.py); physx:game-defaults does not and is shown only to "
        "see how an engine's artefacts move risk. Columns: trials with risk > 0 (of "
        f"{len(ctx.trials)}) and whether each of the paper's risk contrasts comes out (H riskier than E).",
        "",
        *markdown(shown[cols]),
        "",
        "A 3-D rule with a small threshold counts blocks that the noise rule lifts and that then drop a few mm "
        "onto their support as falls (0.1 d = 2.5 mm). Table: `risk_sensitivity.csv` (tidy, one row per engine, "
        "rule, trial, sigma); figure: `figures/risk_sensitivity.png`.",
        "",
    ]
    if (table["risk"].isna()).any():
        bad = table[table["risk"].isna()][["engine", "trial"]].drop_duplicates()
        lines += ["Not simulated (B falls with no noise under that engine): "
                  + ", ".join(f"{e} {t}" for e, t in bad.itertuples(index=False)) + ".", ""]
    for note in notes:
        lines += [f"Left out: {note}.", ""]
    return Section("risk", lines, {"risk_sensitivity": table, "risk_sensitivity_summary": summary},
                   {"figures/risk_sensitivity.png": lambda path: risk_sensitivity_figure(table, path)})

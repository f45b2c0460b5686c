"""The paper's pipeline end to end: stimuli -> physical effort -> physical risk ->
(analysis, when human data are given) -> tidy CSVs, figures, report.md and the results page index.html (lgp/app/page.py).

    python -m lgp.reproduce --quick                 # a small version, about a minute
    python -m lgp.reproduce                         # M = 30 layouts, N = 100 runs, 11 sigmas
    python -m lgp.reproduce --human-data FILE.csv   # plus the Results section (docs/human-data.md)
    python -m lgp.reproduce --quick --sensitivity   # plus risk by engine x fall rule (lgp/app/sensitivity.py)
    python -m lgp.reproduce --fall-rule 3d --fall-threshold 0.1   # the risk model with another fall rule
    python -m lgp.reproduce --sigma-grid wide       # risk past the paper's grid (0.05..0.30 d): "Pairs over sigma"
    python -m lgp.reproduce --noise-rule settle     # noisy blocks set onto their supports instead of lifted
    python -m lgp.reproduce --approach-height 0 --slices 40       # effort with another motion design (docs/effort.md)

Every expensive result (effort of one trial, risk curve of one trial) is cached
under ``<out>/cache`` by a hash of the trial file, the parameters and the code that
computes it, and written atomically: a second run is near instant, and a run killed
half way resumes with nothing lost.
"""
from __future__ import annotations

import argparse
from collections import Counter
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

import stimuli
from lgp import cli
from lgp.paper import N_BOOT, N_SIMS, PAPER_SIGMA, SAMPLES, SIGMA_GRID, SIGMA_GRIDS, TRIAL_IDS
from lgp.executor import default_jobs, executor_for_scheduler, stop_signals
from lgp.app.progress import Progress
from lgp.app.progress import log as progress_log
from lgp.app.cache import LIBRARIES, Cache, files_digest, input_key, library_versions, modules_digest, write_csv_atomic
from lgp.app.manifest import TimedCache, clear_previous, expand, file_sha256, input_hash, write_manifest
from lgp.app.page import Stopwatch, write_index
from lgp.app.replays import write_replays
from lgp.app import sensitivity

PROG = "python -m lgp.reproduce"

QUICK = {"samples": 3, "n_sims": 20, "sigmas": (0.05, 0.065, 0.08, 0.1), "n_boot": 200}


def _log(msg: str) -> None:
    progress_log(msg)  # stderr; above the progress bar on a terminal


def effort_key_inputs() -> dict:
    """What an effort table depends on besides the trial and the parameters: the
    source of every project module physical_effort can run (stimuli draws the
    layouts of A), the arm's model files, and the numerical libraries (SNOPT is Drake's)."""
    return {"code": modules_digest("models.effort", "stimuli"),
            "data": files_digest("models/*.sdf", "models/*.urdf", "models/*.yaml"),
            "libraries": library_versions(("drake", "numpy", "scipy", "pandas"))}


def risk_key_inputs(engine: str | None, fall_rule: str = "horizontal", fall_threshold: float = 0.25,
                    noise_rule: str = "lift") -> dict:
    """What a risk table depends on besides the trial and the parameters: the source
    of every project module risk_table can run (the engine module is loaded by name,
    so it is named here), the engine's settings, the fall rule, and the libraries."""
    from models.risk import DEFAULT_ENGINE, ENGINES, get_engine

    name = DEFAULT_ENGINE if engine is None else engine
    spec = ENGINES[name]
    extra = (spec.requires,) if spec.requires else ()  # e.g. sapien for PhysX
    return {"code": modules_digest("models.risk.core", spec.target.split(":")[0], "stimuli"),
            "engine": name, "engine_settings": get_engine(name).settings(), "libraries": library_versions(LIBRARIES + extra),
            "fall_rule": fall_rule, "fall_threshold": float(fall_threshold), "noise_rule": noise_rule}


def effort_key(trial, samples: int, seed: int, approach_height: float | None = None,
               slices_per_phase: int | None = None) -> str:
    """The cache key of one trial's effort table: the trial file, M, the seed, the
    planner's design (approach height, slices per phase) and effort_key_inputs()."""
    from lgp.planner import APPROACH, SLICES_PER_PHASE, check_design

    h, S = check_design(APPROACH if approach_height is None else approach_height,
                        SLICES_PER_PHASE if slices_per_phase is None else slices_per_phase)
    return input_key(trial=trial.id, digest=trial.digest, samples=samples, seed=seed, approach_height=h,
                     slices_per_phase=S, **effort_key_inputs())


def effort_tables(trials, samples: int, seed: int, executor, cache: Cache, approach_height: float | None = None,
                  slices_per_phase: int | None = None, log: bool = True) -> pd.DataFrame:
    """Per (trial, sample) effort, one cached file per trial (and design: the
    planner's `approach_height` and `slices_per_phase`, defaults when None).

    The layouts of every uncached trial are one stream of work units on the run's
    one executor (warm workers plan across trial boundaries); a trial's file is
    written as soon as its last layout arrives, so an interruption loses at most
    the trials still in flight.
    """
    from models.effort import effort_of_unit, effort_table, effort_units

    from lgp.planner import APPROACH, SLICES_PER_PHASE

    design = {"approach_height": APPROACH if approach_height is None else approach_height,
              "slices_per_phase": SLICES_PER_PHASE if slices_per_phase is None else slices_per_phase}
    keys = {t.id: effort_key(t, samples, seed, **design) for t in trials}
    tables: dict[str, pd.DataFrame] = {}
    for t in trials:
        cached = cache.get("effort", keys[t.id])
        if cached is not None:
            tables[t.id] = cached
    todo = [t for t in trials if t.id not in tables]
    units = [u for t in todo for u in effort_units(t, samples, seed, **design)]
    owner = [u[0] for u in units]
    pending = Counter(t.id for t in owner)
    rows: dict[str, list[dict]] = {t.id: [] for t in todo}
    t0 = time.perf_counter()
    bar = Progress("effort", len(units), "plans")

    def arrived(k, row):
        bar.advance()
        trial = owner[k]
        rows[trial.id].append(row)
        pending[trial.id] -= 1
        if pending[trial.id] == 0:
            tables[trial.id] = cache.put("effort", keys[trial.id], effort_table(trial, samples, rows[trial.id]))
            df = tables[trial.id]
            if log:
                _log(f"[effort {len(tables):2d}/{len(trials)}] {trial.id:>3}: {df['effort'].mean():9.4f} J*s over {len(df)} layouts"
                     f"  (planned, {time.perf_counter() - t0:.1f} s into the stage)")

    for t in trials:
        if log and t.id in tables and t.id not in rows:
            _log(f"[effort {trials.index(t) + 1:2d}/{len(trials)}] {t.id:>3}: {tables[t.id]['effort'].mean():9.4f} J*s"
                 f" over {len(tables[t.id])} layouts  (cached)")
    with bar:
        executor.map(effort_of_unit, units, arrived)
    return pd.concat([tables[t.id] for t in trials], ignore_index=True)


#: The per-run columns a run caches (what the risk table and the required
#: precision's bootstrap over runs are computed from).
RUN_CACHE_COLUMNS = ["trial", "sigma", "run", "fell", "engine", "fall_rule", "fall_threshold", "noise_rule"]


def risk_tables(trials, sigmas, n_sims: int, seed: int, engine: str | None, executor, cache: Cache, chunk: int = 6,
                fall_rule: str = "horizontal", fall_threshold: float = 0.25, noise_rule: str = "lift",
                runs_out: list | None = None) -> pd.DataFrame:
    """Per (trial, sigma) risk, one cached file per trial (common random numbers over sigma).

    Each trial's cached file holds its runs' verdicts (RUN_CACHE_COLUMNS); the
    risk table (with its Wilson intervals) is summarised from them, and
    `runs_out`, when given, receives the per-run table (for the required precision).
    Uncached trials are simulated a few at a time on the run's one executor, so
    the grid keeps every worker busy and an interruption loses at most one chunk.
    """
    from models.risk import risk_table, summarise

    depends = risk_key_inputs(engine, fall_rule, fall_threshold, noise_rule)
    keys = {t.id: input_key(trial=t.id, digest=t.digest, sigmas=list(sigmas), n_sims=n_sims, seed=seed, **depends) for t in trials}
    tables = {t.id: cache.get("riskruns", keys[t.id]) for t in trials}
    todo = [t for t in trials if tables[t.id] is None]
    bar = Progress("risk", len(todo) * len(sigmas) * n_sims, "runs")
    for k in range(0, len(todo), chunk):
        group = todo[k:k + chunk]
        t0 = time.perf_counter()
        base = bar.done
        table = risk_table(group, sigmas=list(sigmas), n_sims=n_sims, seed=seed, engine=engine, executor=executor,
                           fall_rule=fall_rule, fall_threshold=fall_threshold, noise_rule=noise_rule, runs=True,
                           progress=lambda done, total: bar.advance(base + done - bar.done))[RUN_CACHE_COLUMNS]
        for t in group:
            tables[t.id] = cache.put("riskruns", keys[t.id], table[table["trial"] == t.id].reset_index(drop=True))
        _log(f"[risk] simulated {', '.join(t.id for t in group)}: {len(group) * len(sigmas) * n_sims} runs in {time.perf_counter() - t0:.1f} s")
    if todo:
        bar.close()
    out = []
    for k, trial in enumerate(trials, 1):
        if runs_out is not None:
            runs_out.append(tables[trial.id])
        df = summarise(tables[trial.id].assign(trial=tables[trial.id]["trial"].astype(str)))
        curve = " ".join(f"{r:.2f}" for r in df.sort_values("sigma")["risk"])
        _log(f"[risk   {k:2d}/{len(trials)}] {trial.id:>3}: risk over sigma {curve}  ({'cached' if trial not in todo else 'new'})")
        out.append(df)
    return pd.concat(out, ignore_index=True)


def check_targets(trials, engine: str | None, cache: Cache, fall_rule: str = "horizontal", fall_threshold: float = 0.25) -> None:
    """Before the long work: B of every trial must stand unperturbed (the risk
    model's sigma = 0 run), one simulation per trial, cached like the results.
    Raises UnstableSceneError naming every trial whose B falls and its blocks."""
    from models.risk import UnstableSceneError, check_stable

    depends = risk_key_inputs(engine, fall_rule, fall_threshold)
    problems = []
    for t in trials:
        key = input_key(trial=t.id, digest=t.digest, check="B stands unperturbed", **depends)
        df = cache.get("stable", key)
        if df is None:
            try:
                check_stable(t.target, engine, fall_rule=fall_rule, fall_threshold=fall_threshold)
                df = pd.DataFrame([{"trial": t.id, "stable": True, "problem": ""}])
            except UnstableSceneError as e:
                df = pd.DataFrame([{"trial": t.id, "stable": False, "problem": str(e)}])
            cache.put("stable", key, df)
        if not bool(df["stable"].iloc[0]):
            problems.append(str(df["problem"].iloc[0]))
    if problems:
        raise UnstableSceneError("; ".join(problems))


def kappa_range(E_e: float, R_e: float, E_h: float, R_h: float) -> str:
    """Ratios k = b2/b1 (b1 > 0, k >= 0) for which Eq. 1 costs E less than H.

    Eq. 1 cost over b1 is E(1 - R) + k E R (+ const), so cost_H - cost_E is
    a + k b with a = E_h(1 - R_h) - E_e(1 - R_e) and b = E_h R_h - E_e R_e:
    linear in k, and the set where it is positive is a half-line.
    """
    a = E_h * (1 - R_h) - E_e * (1 - R_e)
    b = E_h * R_h - E_e * R_e
    if b == 0:
        return "any" if a > 0 else "none"
    k = -a / b
    if b > 0:
        return "any" if k < 0 else f"> {k:.3g}"
    return "none" if k <= 0 else f"< {k:.3g}"


def pair_orderings(effort: pd.DataFrame, risk: pd.DataFrame, sigma: float, trials) -> pd.DataFrame:
    """Per pair: effort and risk (at `sigma`) of E and H, whether E < H in each, and
    the ratios b2/b1 for which the full model (Eq. 1) would order the pair E < H."""
    from analysis import pair_table, risk_at_sigma

    dims = {t.pair: t.dimension for t in trials}
    e = pair_table(effort.set_index("trial")["effort"]).rename(
        columns={"cost_E": "effort_E", "cost_H": "effort_H", "order": "effort_order", "E_lt_H": "effort_E_lt_H"})
    r = pair_table(risk_at_sigma(risk, sigma)).rename(
        columns={"cost_E": "risk_E", "cost_H": "risk_H", "order": "risk_order", "E_lt_H": "risk_E_lt_H"})
    table = e.merge(r, on="pair")
    table.insert(1, "dimension", table["pair"].map(dims))
    table.insert(4, "effort_rel_diff", (table["effort_H"] - table["effort_E"]) / table["effort_E"])
    table.insert(table.columns.get_loc("risk_E"), "sigma", sigma)
    return _with_full_model_range(table)


def _with_full_model_range(table: pd.DataFrame) -> pd.DataFrame:
    """Add the ratios b2/b1 for which Eq. 1 orders each pair E < H; a pair tied in
    effort and in risk (analysis.pairs.TIE_REL) is tied by Eq. 1 for every b."""
    table["full_E_lt_H_for_b2_over_b1"] = [
        "none (tie)" if (eo == "tie" and ro == "tie") else kappa_range(*row)
        for row, eo, ro in zip(table[["effort_E", "risk_E", "effort_H", "risk_H"]].to_numpy(),
                               table["effort_order"], table["risk_order"])]
    return table


def declared_pair_orderings(effort: pd.DataFrame, risk: pd.DataFrame, sigma: float, trials) -> pd.DataFrame | None:
    """pair_orderings (same columns, same tie rule) for a stimulus set other than
    the paper's: the pairs whose E and H trials (ids <pair>E, <pair>H) are both in
    the run; None when there are none."""
    from analysis.pairs import pair_order

    ids = {t.id for t in trials}
    declared = sorted({t.pair for t in trials if t.pair is not None and {f"{t.pair}E", f"{t.pair}H"} <= ids})
    if not declared:
        return None
    at = risk[np.isclose(risk["sigma"].astype(float), sigma, rtol=0, atol=1e-9)]
    costs = {"effort": effort.set_index("trial")["effort"].astype(float), "risk": at.set_index("trial")["risk"].astype(float)}
    table = pd.DataFrame({"pair": declared})
    for name, cost in costs.items():
        table[f"{name}_E"] = [cost[f"{p}E"] for p in declared]
        table[f"{name}_H"] = [cost[f"{p}H"] for p in declared]
        table[f"{name}_order"] = [pair_order(e, h) for e, h in zip(table[f"{name}_E"], table[f"{name}_H"])]
        table[f"{name}_E_lt_H"] = table[f"{name}_order"] == "E<H"
    table.insert(1, "dimension", table["pair"].map({t.pair: t.dimension for t in trials}))
    table.insert(4, "effort_rel_diff", (table["effort_H"] - table["effort_E"]) / table["effort_E"])
    table.insert(table.columns.get_loc("risk_E"), "sigma", sigma)
    return _with_full_model_range(table)


def _orders(pairs: pd.DataFrame, source: str) -> str:
    """'E < H in 10 of 12 pairs (tied: 6; reversed: 11)' from a pair table."""
    n = int(pairs[f"{source}_E_lt_H"].sum())
    notes = []
    for order, word in (("tie", "tied"), ("H<E", "reversed")):
        found = pairs.loc[pairs[f"{source}_order"] == order, "pair"].tolist()
        if found:
            notes.append(f"{word}: {', '.join(map(str, found))}")
    return f"E < H in {n} of {len(pairs)} pairs" + (f" ({'; '.join(notes)})" if notes else "")


def engine_description(engine: str | None, settings: dict | None = None) -> str:
    """The risk engine by name with its settings, e.g. 'mujoco 3.3.0 (timestep 0.002, ...)'."""
    from models.risk.core import DEFAULT_ENGINE
    from models.risk.engine import get_engine

    name = engine or DEFAULT_ENGINE
    settings = dict(get_engine(name).settings() if settings is None else settings)
    settings.pop("engine", None)
    version = settings.pop("version", None)
    text = ", ".join(f"{k} {v}" for k, v in settings.items())
    return f"{name}" + (f" {version}" if version else "") + (f" ({text})" if text else "") + \
        ("" if engine else " [the default engine]") + \
        (" [UNFAITHFUL profile: fails the faithfulness suite, docs/risk.md]" if settings.get("faithful") is False else "")


def _markdown(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, row in df.iterrows():
        cells = [format(v, floatfmt) if isinstance(v, (float, np.floating)) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _design_text(approach_height: float | None, slices: int | None) -> str:
    """'5 cm approach legs, 20 slices per phase' (or the clearance design at height 0)."""
    from lgp.planner import APPROACH, SLICES_PER_PHASE

    h = APPROACH if approach_height is None else approach_height
    legs = f"{h * 100:g} cm approach legs" if h > 0 else "no approach legs (clearance constraint)"
    return f"{legs}, {SLICES_PER_PHASE if slices is None else slices} slices per phase"


def write_report(out: Path, args, effort: pd.DataFrame, risk: pd.DataFrame, pairs: pd.DataFrame, analysis: dict | None,
                 elapsed: float, software: dict | None = None, compute: tuple[float, int] = (float("nan"), 0)) -> Path:
    """report.md: settings, the engine with its settings, both times, the tables, and
    the pair orderings under the one tie rule (analysis.pairs.TIE_REL)."""
    from analysis.pairs import TIE_REL

    engine = engine_description(args.engine, (software or {}).get("engine"))
    wide = risk.pivot_table(index="trial", columns="sigma", values="risk").reindex(effort["trial"])
    wide.columns = [f"{s:g}" for s in wide.columns]
    compute_s, unknown = compute
    compute_text = (f"Compute time of these results {compute_s:.0f} s (wall time spent computing each cached effort and risk "
                    "result when it was computed" + (f"; {unknown} result(s) cached by an older version have no recorded time"
                                                     if unknown else "") + f"); this run took {elapsed:.0f} s.")
    lines = [
        "# Reproduction report",
        "",
        f"Settings: trials {len(effort)}, M = {args.samples} layouts, N = {args.n_sims} runs per sigma, "
        f"sigmas {', '.join(f'{s:g}' for s in args.sigmas)} (x d), "
        f"fall rule {getattr(args, 'fall_rule', 'horizontal')} > {getattr(args, 'fall_threshold', 0.25):g} d, "
        f"noise rule {getattr(args, 'noise_rule', 'lift')}, seed {args.seed}, "
        f"effort planned with {_design_text(getattr(args, 'approach_height', None), getattr(args, 'slices', None))}"
        + (" (--quick: a small version; numbers are noisier than the full run)" if args.quick else "") + ".",
        f"Risk engine: {engine or args.engine or 'default'}.",
        compute_text,
        "",
        "## Physical effort (J*s: integral of the carried blocks' kinetic energy over time, 1 kg blocks)",
        "",
        _markdown(effort),
        "",
        "## Physical risk (fraction of noisy runs that fall)",
        "",
        _markdown(wide.reset_index(), ".2f"),
        "",
    ]
    if pairs is not None:
        lines += [
            f"## Easy/hard pairs (risk at sigma = {pairs['sigma'].iloc[0]:g} d)",
            "",
            _markdown(pairs.drop(columns=["sigma"])),
            "",
            f"Tie rule (one rule for this table, pairs.csv, the figures and docs/results.md): E and H are tied when "
            f"|H - E| <= {TIE_REL:g} x max(E, H), the plan-to-plan noise of effort (analysis.pairs.TIE_REL); "
            "a tie counts as not ordered. effort_rel_diff = (H - E) / E.",
            "",
            f"Effort: {_orders(pairs, 'effort')}. Risk: {_orders(pairs, 'risk')}. "
            "The paper's fitted full model ordered 11 of 12 (pair 11 the exception).",
            "",
        ]
        if analysis is None:
            lines += ["Without human data there are no fitted betas, so the last column says for which ratios b2/b1 "
                      "(b1 > 0) Eq. 1 would order each pair E < H.", ""]
        else:
            lines += ["The last column says for which ratios b2/b1 (b1 > 0) Eq. 1 would order each pair E < H; the "
                      "fitted betas and the orderings they give are below.", ""]
    if analysis is None:
        lines += ["No human data given (`--human-data FILE`, format in docs/human-data.md): the fits of Eq. 1, "
                  "the sigma profile and the bootstrap need the responses, which are not public.", ""]
    else:
        for key in ("sigma_choice", "fits", "bootstrap_summary", "bootstrap_tests"):
            if key in analysis and isinstance(analysis[key], pd.DataFrame) and len(analysis[key]):
                lines += [f"## {key.replace('_', ' ')}", "", _markdown(analysis[key]), ""]
        if "orderings" in analysis:
            lines += ["## Pair orderings by source (orderings.csv)", "", _markdown(analysis["orderings"]), ""]
    if software:  # what the cache keys hold besides code and inputs: a reader can tell which library made the numbers
        lines += ["## Software", "", "Libraries: " + ", ".join(f"{k} {v}" for k, v in software["libraries"].items()) + ".",
                  "", f"Risk engine settings: `{json.dumps(software['engine'], sort_keys=True, default=str)}`.", ""]
    path = out / "report.md"
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines))
    os.replace(tmp, path)
    return path



def parse_args(argv=None) -> argparse.Namespace:
    """The command line, checked: every count, sigma, trial id and path is refused
    here, in one line, before any work (lgp.cli)."""
    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="results", type=cli.output_dir,
                   help="output directory (default: results/); an earlier run's outputs in it are removed, its cache kept")
    p.add_argument("--stimuli", metavar="DIR", type=cli.input_dir,
                   help="run on the trial files of DIR (default: stimuli/trials, the paper's): all of them unless --trials "
                   "names some; pair table only for pairs whose E and H files are both there")
    p.add_argument("--trials", nargs="+", type=cli.trial_id_or_all,
                   help="trial ids (case-insensitive), or 'all' for every trial file (default: the paper's 24)")
    p.add_argument("--samples", type=cli.positive_int, help="M, random layouts of A per trial (default 30; --quick 3)")
    p.add_argument("--n-sims", type=cli.positive_int, help="N, noisy simulations per trial and sigma (default 100; --quick 20)")
    grid = p.add_mutually_exclusive_group()
    grid.add_argument("--sigmas", type=cli.sigma, nargs="+", help="noise levels in (0, 1], units of d (default: 0.05..0.10 step 0.005)")
    grid.add_argument("--sigma-grid", choices=list(SIGMA_GRIDS),
                      help="a named sigma grid: paper (default) or wide (0.05..0.30 d step 0.01 plus the paper's points)")
    p.add_argument("--noise-rule", choices=["lift", "settle"], default="lift",
                   help="heights of the noisy blocks: lift (default) or settle (every block rests on what lies beneath it; docs/risk.md)")
    p.add_argument("--engine", help="physics engine for risk: mujoco, drake, physx (optional extra) (default: mujoco)")
    p.add_argument("--profile", help="engine profile: faithful (default) or, for physx, game-defaults (UNFAITHFUL; docs/risk.md)")
    p.add_argument("--fall-rule", default="horizontal", help="a run falls by horizontal (default) or 3d displacement")
    p.add_argument("--fall-threshold", type=float, default=0.25, help="fall threshold in units of d (default %(default)s)")
    p.add_argument("--approach-height", type=cli.approach_height, default=None,
                   help="effort: vertical approach/retreat leg (m) at every grasp and place; 0 = a clearance constraint "
                        "instead (default 0.05; docs/effort.md)")
    p.add_argument("--slices", type=cli.positive_int, default=None,
                   help="effort: KOMO slices per 1 s phase (default 20; docs/effort.md, time discretisation)")
    p.add_argument("--jobs", type=cli.positive_int, default=default_jobs(),
                   help="processes, or LocalCluster workers with --scheduler local-dask, >= 1 (default: all cores, %(default)s here)")
    p.add_argument("--scheduler", help="run the work units on Dask: tcp://HOST:8786 (a running scheduler) or local-dask "
                   "(a LocalCluster of --jobs workers); default: a local process pool. Needs the [dask] extra (docs/scaling.md)")
    p.add_argument("--seed", type=cli.seed, default=0)
    p.add_argument("--n-boot", type=cli.positive_int, help="bootstrap resamples (default 1000; --quick 200)")
    p.add_argument("--human-data", type=cli.input_file, help="CSV of human responses (docs/human-data.md); needs the paper's 24 trials")
    p.add_argument("--quick", action="store_true", help="small M, N and sigma grid: about a minute")
    p.add_argument("--no-cache", action="store_true", help="recompute everything")
    p.add_argument("--no-replays", action="store_true", help="skip the 3-D replays of the results page (replays/<trial>.html)")
    p.add_argument("--risk-chunk", type=cli.positive_int, default=6, help="trials simulated per process-pool batch (an interruption loses at most one)")
    p.add_argument("--build-risk", action="store_true", help="also risk through the build, at --build-sigmas (lgp/app/build_risk.py)")
    p.add_argument("--build-sigmas", type=cli.sigma, nargs="+", help="noise levels of --build-risk in (0, 1] (default 0.065 0.1)")
    p.add_argument("--risk-measure", choices=["final", "max", "expected", "any", "care", "sequential"],
                   help="with --build-risk and --human-data: this build-risk aggregate replaces R in Eq. 1")
    p.add_argument("--per-participant-sigma", action="store_true", help="with --human-data: each participant's sigma")
    p.add_argument("--participant-betas", choices=["shared", "participant"], default="shared",
                   help="betas of --per-participant-sigma (default: b2/b1 shared per dataset)")
    sensitivity.add_arguments(p)
    args = p.parse_args(argv)
    try:  # bad engine, profile, rule or threshold: one line, before any work
        from models.risk import check_fall_rule, engine_name

        if args.engine is not None or args.profile is not None:
            args.engine = engine_name(args.engine or "mujoco", args.profile)
        check_fall_rule(args.fall_rule, args.fall_threshold)
        sensitivity.check_arguments(args)
    except ValueError as e:
        p.exit(2, f"{p.prog}: error: {e}\n")
    if args.risk_measure and not (args.build_risk and args.human_data):
        p.error("--risk-measure needs --build-risk and --human-data")
    if args.per_participant_sigma and not args.human_data:
        p.error("--per-participant-sigma needs --human-data FILE")
    args.command = "python -m lgp.reproduce " + " ".join(argv if argv is not None else sys.argv[1:])
    q = QUICK if args.quick else {}
    args.samples = args.samples if args.samples is not None else q.get("samples", SAMPLES)
    args.n_sims = args.n_sims if args.n_sims is not None else q.get("n_sims", N_SIMS)
    args.sigmas = tuple(dict.fromkeys(SIGMA_GRIDS[args.sigma_grid] if args.sigma_grid else
                                      args.sigmas or q.get("sigmas", SIGMA_GRID)))
    args.n_boot = args.n_boot if args.n_boot is not None else q.get("n_boot", N_BOOT)
    from lgp.planner import APPROACH, SLICES_PER_PHASE

    args.approach_height = APPROACH if args.approach_height is None else args.approach_height
    args.slices = SLICES_PER_PHASE if args.slices is None else args.slices
    if args.trials:
        args.trials = list(dict.fromkeys(args.trials))  # 7h and 7H are one trial
        if "all" in args.trials and len(args.trials) > 1:
            p.error("--trials all runs every trial file; give it alone")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    with stop_signals() as stop:  # `timeout`, `kill` and schedulers stop a run as Ctrl-C does
        try:
            return run(args, argv)
        except BaseException as e:
            if stop.received is None and not isinstance(e, KeyboardInterrupt):
                raise
            sig = stop.received or getattr(e, "signal", signal.SIGINT)
            how = "terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted"
            resume = "nothing cached (--no-cache)" if args.no_cache else f"finished trials are cached in {Path(args.out) / 'cache'}, rerun to resume"
            print(f"{PROG}: {how}; {resume}", file=sys.stderr)
            return 128 + int(sig)


def select_trials(ids: list[str] | None, directory=None) -> list:
    """The trials of a run: the paper's 24 by default (other trial files in the
    directory are named, not run), ``all`` for every trial file, or the ids given."""
    if not ids and directory is not None:  # a user's stimulus set (--stimuli DIR): every trial file in it
        if not stimuli.trial_ids(directory):
            raise stimuli.StimulusError(f"--stimuli {directory}: no trial files (*.yaml) there")
        return stimuli.load_all(directory)
    if not ids:
        extra = stimuli.extra_ids(directory)
        if extra:
            _log(f"the trial folder also holds {', '.join(extra)} (not among the paper's 24): "
                 f"run them with --trials {' '.join(extra)} or --trials all")
        return stimuli.load_paper(directory)
    if [t.lower() for t in ids] == ["all"]:
        return stimuli.load_all(directory)
    return [stimuli.load_trial(t, directory) for t in ids]


def run(args, argv=None) -> int:
    """The pipeline for parsed command-line `args` (see `main`)."""
    t0 = time.perf_counter()
    clock = Stopwatch()  # wall time per stage, for the results page
    # Validate every input before anything is written or computed.
    trials = select_trials(args.trials, args.stimuli)
    human = None
    if args.human_data:
        from analysis import load_human_data

        human = load_human_data(args.human_data)
        if not {t.id for t in trials} >= set(TRIAL_IDS):
            raise ValueError("--human-data needs the paper's 24 trials (the fits compare the 12 pairs); drop --trials")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    removed = clear_previous(out)  # this folder describes this run only (lgp/app/manifest.py)
    if removed:
        _log(f"removed the outputs of an earlier run from {out}: {', '.join(removed)} (the cache is kept)")
    cache = TimedCache(out / "cache", enabled=not args.no_cache)
    _log(f"lgp.reproduce: {len(trials)} trials, M={args.samples}, N={args.n_sims}, {len(args.sigmas)} sigmas, jobs={args.jobs}"
         f"{', scheduler ' + args.scheduler if args.scheduler else ''}; cache {cache.root}")

    # One executor for the whole run: its workers start now, before this process
    # imports Drake or MuJoCo, and stay warm across trials and stages.
    # SchedulerUnreachable / DaskMissing: one line from lgp.cli, exit 1
    with executor_for_scheduler(args.scheduler, args.jobs) as executor, cache.stage():
        if hasattr(executor, "start"):
            executor.start()
        with cli.deferred_interrupt():  # Drake loads here; a Ctrl-C meanwhile waits until it has
            import models.effort  # noqa: F401
            import models.risk  # noqa: F401
        from models.effort import summarise_effort
        check_targets(trials, args.engine, cache, args.fall_rule, args.fall_threshold)  # an unstable B fails now, not after the effort stage
        effort_samples = effort_tables(trials, args.samples, args.seed, executor, cache,
                                       approach_height=args.approach_height, slices_per_phase=args.slices)
        clock.lap("effort")
        effort = summarise_effort(effort_samples, trials)
        risk_runs: list = []
        risk = risk_tables(trials, args.sigmas, args.n_sims, args.seed, args.engine, executor, cache, args.risk_chunk,
                           fall_rule=args.fall_rule, fall_threshold=args.fall_threshold, noise_rule=args.noise_rule,
                           runs_out=risk_runs)
        clock.lap("risk")
        sensitive = sensitivity.run_sections(sensitivity.Context(args, trials, executor, cache, out, risk_key_inputs, _log,
                                                                     effort_tables=effort_tables)) \
            if args.sensitivity else []
        if args.sensitivity:
            clock.lap("sensitivity")
        if args.build_risk:
            from lgp.app import build_risk

            stages = build_risk.build_risk_tables(trials, args.build_sigmas or build_risk.BUILD_SIGMAS, args.n_sims,
                                                   args.samples, args.seed, args.engine, executor, cache,
                                                   fall_rule=args.fall_rule, fall_threshold=args.fall_threshold,
                                                   approach_height=args.approach_height, noise_rule=args.noise_rule)
            clock.lap("build risk")
        replays = None if args.no_replays else write_replays(
            trials, args.seed, out / "replays", cache, executor, _log,
            planner_options={"approach_height": args.approach_height, "slices_per_phase": args.slices})
        clock.lap("replays")
    sigma = PAPER_SIGMA if any(np.isclose(args.sigmas, PAPER_SIGMA)) else args.sigmas[len(args.sigmas) // 2]
    written = [write_csv_atomic(effort_samples, out / "effort_samples.csv"), write_csv_atomic(effort, out / "effort.csv"),
               write_csv_atomic(risk, out / "risk.csv")]
    from models.risk.precision import required_precision

    precision = required_precision(pd.concat(risk_runs, ignore_index=True), n_boot=args.n_boot, seed=args.seed)
    written.append(write_csv_atomic(precision, out / "risk_precision.csv"))
    if replays:
        written += [Path(p) for p in replays.values()]
    sections, build, over_html = [], None, None
    for s in sensitive:  # --sensitivity (lgp/app/sensitivity.py)
        written += s.files
        sections.append("\n".join(s.lines))
    if args.build_risk:
        paths, section, build = build_risk.build_risk_outputs(stages, out, args.command)
        written += paths
        sections.append(section)
    pairs, analysis = None, None
    if {t.id for t in trials} >= set(TRIAL_IDS):
        # Pair orderings, figures and fits are the paper's: on its 24 trials only;
        # other trials of the run are in the effort and risk tables.
        from analysis import run_analysis

        paper = [t for t in trials if t.id in TRIAL_IDS]
        extra = [t.id for t in trials if t.id not in TRIAL_IDS]
        if extra:
            _log(f"pair table, figures and fits use the paper's 24 trials; {', '.join(extra)} are in the effort and risk tables only")
        e_samples, e_mean, r = (df[df["trial"].isin(TRIAL_IDS)] for df in (effort_samples, effort, risk))
        pairs = pair_orderings(e_mean, r, sigma, paper)
        written.append(write_csv_atomic(pairs, out / "pairs.csv"))
        from lgp.app import over_sigma  # "Pairs over sigma" (issue 22)

        over = over_sigma.pairs_over_sigma(e_mean, r)
        written.append(write_csv_atomic(over, out / "pairs_over_sigma.csv"))
        over_figure = over_sigma.plot_risk_over_sigma(over, out / "figures" / "risk_over_sigma.png",
                                                      {t.pair: t.dimension for t in paper})
        written.append(over_figure)
        sections.insert(0, "\n".join(over_sigma.report_lines(over, precision, "figures/risk_over_sigma.png")))
        over_html = over_sigma.page_section(over, over_figure, out)
        analysis = run_analysis(human, e_samples, r, out / ("analysis" if human is not None else "figures"),
                                seed=args.seed, n_boot=args.n_boot, jobs=args.jobs, sigma=None if human is not None else sigma,
                                build_risk=None if human is None or build is None else build[build["trial"].isin(TRIAL_IDS)],
                                risk_measure=args.risk_measure)
        written += [Path(path) for path in analysis["files"]["path"]]
        if args.per_participant_sigma:
            from lgp.app import build_risk

            paths, section = build_risk.participant_sigma_outputs(human, e_samples, r, out,
                                                                   args.participant_betas, args.command)
            written += paths
            sections.append(section)
    else:
        from lgp.app.over_sigma import precision_lines

        sections.insert(0, "\n".join(precision_lines(precision)))
        pairs = declared_pair_orderings(effort, risk, sigma, trials)
        if pairs is not None:
            written.append(write_csv_atomic(pairs, out / "pairs.csv"))
        _log("not all of the paper's 24 trials: no figures or fits (they need all 24); "
             + (f"pair table for the {len(pairs)} pair(s) whose E and H trials are both in the run" if pairs is not None
                else "no pair table (no trial files declare both trials of a pair)"))
    clock.lap("analysis")
    software = {"libraries": library_versions(), "engine": risk_key_inputs(args.engine)["engine_settings"]}
    compute = cache.compute_time()
    report = write_report(out, args, effort, risk, pairs, analysis if human is not None else None,
                          time.perf_counter() - t0, software, compute)
    if sections:
        from lgp.app.build_risk import append_report

        append_report(report, sections)
    written.append(report)
    written.append(write_index(out, args, trials, effort_samples, risk, sigma, pairs, analysis, cache, clock, replays,
                               over_sigma_html=over_html, precision=precision))
    if (out / "page").is_dir():
        written.append(out / "page")
    _log(f"cache: {cache.summary()}")
    parameters = {"trials": [t.id for t in trials], "samples": args.samples, "n_sims": args.n_sims,
                  "sigmas": list(args.sigmas), "sigma_of_pairs": sigma if pairs is not None else None,
                  "engine": args.engine, "seed": args.seed, "n_boot": args.n_boot, "quick": args.quick,
                  "no_cache": args.no_cache, "build_risk": args.build_risk, "build_sigmas": args.build_sigmas,
                  "risk_measure": args.risk_measure, "per_participant_sigma": args.per_participant_sigma,
                  "profile": args.profile, "fall_rule": args.fall_rule, "fall_threshold": args.fall_threshold,
                  "sigma_grid": args.sigma_grid, "noise_rule": args.noise_rule,
                  "sensitivity": getattr(args, "sensitivity", None), "approach_height": args.approach_height,
                  "slices_per_phase": args.slices}
    inputs = {"trial_files": {t.id: t.digest for t in trials},
              "human_data_sha256": file_sha256(args.human_data) if args.human_data else None}
    files = list(dict.fromkeys(expand(written)))
    manifest = write_manifest(out, files, command=[PROG, *(sys.argv[1:] if argv is None else argv)],
                              parameters=parameters, inputs=inputs, input_hash=input_hash(**parameters, **inputs),
                              engine=engine_description(args.engine, software["engine"]), software=software,
                              run_time_s=round(time.perf_counter() - t0, 1),
                              compute_time_s=round(compute[0], 1), compute_time_unknown_results=compute[1])
    print(f"Outputs of this run in {out.resolve()} (listed in {manifest.name}):")
    for path in files + [manifest]:
        print(f"  {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))

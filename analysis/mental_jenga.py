"""The risk engine against another lab's human judgments of what falls (issue 33):
Mental Jenga (Zhou, Smith, Tenenbaum & Gerstenberg 2023), read from a user's clone
of `cicl-stanford/mental_jenga` (stimuli/mental_jenga.py).

    python -m analysis.mental_jenga --repo PATH --experiment 2 --out DIR [--runs 100] [--jobs 2] [--engine mujoco]

Per noise rule and sigma on a grid: the model's mean count of red bricks off the
table per scene (models/counterfactual.py: by default in the authors' exact engine,
box2dweb through Node, with their x-only noise; pybox2d, MuJoCo or PhysX with
--engine, the last two also drawing the paper's 3-D rule) against the human mean per
scene: Pearson r and RMSE of the raw counts (no linear map: the model predicts a
count in the same unit as the answer). The best sigma is the one of least RMSE
(ties to the smaller sigma), with a bootstrap interval over participants
(participants resampled, the human means and the best sigma recomputed; the
model's means fixed); the held-out r chooses sigma on the other 41 scenes
(leave-one-scene-out, least RMSE) and correlates each scene's prediction at its
own held-out sigma with people. Writes DIR/fit.csv, DIR/scenes.csv (per scene and
sigma), DIR/runs.csv is not written (the per-run tables are the cache,
DIR/cache/), DIR/summary.json and DIR/scatter.png (model vs people at the best
sigma, the authors' perceptual-noise model at its best level beside it).
Nothing here is fitted to Experiment 1: run it once, after Experiment 2.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.errors import InputError
from lgp.command_times import cpu_seconds
from stimuli.mental_jenga import BRICK_A, MentalJengaError, read_predictions, read_scenes

#: sigma grids: authors' units for "authors-x" (their level k is 0.03 k), a fraction
#: of the brick's edge along each axis for "paper-3d".
DEFAULT_GRID = tuple(round(0.01 * k, 2) for k in range(31))
RULES = ("authors-x", "paper-3d")
#: The command's engine: the authors' exact one, box2dweb (Box2D 2.1a in JavaScript,
#: through Node; models/box2dweb_engine.py). It reproduces their saved perceptual-noise
#: runs run for run (every one of the first 100 runs of the 42 scenes of experiment 2
#: at level 8); pybox2d ("box2d", Box2D 2.3) does not: it finds other contact points
#: and loses no brick in scenes 26 and 35 (docs/mental-jenga.md).
DEFAULT_ENGINE = "box2dweb"
#: The 2-D engines (the authors' world) and their rules: the authors' own.
ENGINES_2D = ("box2dweb", "box2d")
BOX2D_RULES = ("authors-x",)
KIND = "mjruns"


# ----------------------------------------------------------------------------- simulation (cached, both cores)


def _code_key(engine: str = "mujoco") -> dict:
    from lgp.app.cache import library_versions, modules_digest

    if engine == "box2d":
        return {"code": modules_digest("models.counterfactual", "models.box2d_engine"),
                "libraries": library_versions(("numpy", "Box2D"))}
    if engine == "box2dweb":
        from models.box2dweb_engine import engine_versions, node_version

        return {"code": modules_digest("models.counterfactual", "models.box2dweb_engine"),
                "libraries": library_versions(("numpy",)), "box2dweb": {**engine_versions(), "node": node_version()}}
    libs = ("mujoco", "numpy") if engine == "mujoco" else ("mujoco", "numpy", "sapien")
    return {"code": modules_digest("models.counterfactual"), "libraries": library_versions(libs)}


def _simulate(scene, rule, sigmas, n_runs, seed, engine="mujoco"):
    from models.counterfactual import counterfactual_runs

    t0 = cpu_seconds()
    df = counterfactual_runs(scene, rule, sigmas, n_runs, seed, engine=engine)
    return df, cpu_seconds() - t0


def simulate_all(scenes, rules, sigmas, n_runs: int, seed: int, cache_dir: Path, jobs: int = 2, log=None,
                 engine: str = "mujoco"):
    """Per-run table of every (scene, rule): trial, rule, sigma, run, fallen, ids;
    each (scene, rule) a cache entry keyed by its inputs, computed on `jobs` processes."""
    from lgp.app.cache import Cache, input_key
    from models.counterfactual import FallSettings

    log = sys.stderr if log is None else log  # the stream of the moment (a default bound at import outlives a test's capture)

    cache = Cache(cache_dir)
    base = {**_code_key(engine), "settings": FallSettings().as_dict(), "sigmas": list(map(float, sigmas)), "runs": n_runs, "seed": seed}
    extra = {}  # MuJoCo runs keep the keys they had
    if engine == "physx":
        from dataclasses import asdict

        from models.risk.physx_engine import PROFILES

        extra = {"engine": engine, "physx": asdict(PROFILES["faithful"])}
    elif engine in ENGINES_2D:
        base.pop("settings")  # the Box2D worlds have the authors' settings only (models/box2d_engine.py)
        extra = {"engine": engine}
    tables, todo = {}, []
    for s in scenes:
        for rule in rules:
            key = input_key(scene=s.digest, label=s.label, rule=rule, **base, **extra)
            df = cache.get(KIND, key)
            if df is not None:
                tables[s.label, rule] = df
            else:
                todo.append((s, rule, key))
    cpu = 0.0
    if todo:
        print(f"analysis.mental_jenga: simulating {len(todo)} scene x rule tables "
              f"({len(todo) * len(sigmas) * n_runs} runs) on {jobs} processes", file=log, flush=True)
        t0 = time.time()
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(_simulate, s, rule, list(sigmas), n_runs, seed, engine): (s, rule, key) for s, rule, key in todo}
            for k, f in enumerate(as_completed(futures), 1):
                s, rule, key = futures[f]
                df, c = f.result()
                cpu += c
                tables[s.label, rule] = cache.put(KIND, key, df)
                print(f"  {k}/{len(todo)} {s.label} {rule}: {time.time() - t0:.0f} s", file=log, flush=True)
    out = pd.concat([tables[s.label, r] for s in scenes for r in rules], ignore_index=True)
    out["trial"] = out["trial"].astype(str)
    return out, {"computed": len(todo), "cached": len(scenes) * len(rules) - len(todo), "cpu_s": cpu}


# ----------------------------------------------------------------------------- statistics


def fit_stats(model: np.ndarray, human: np.ndarray) -> tuple[float, float]:
    """(Pearson r, RMSE) of model means against human means, no linear map. r is nan
    when the model is constant over scenes."""
    rmse = float(np.sqrt(np.mean((model - human) ** 2)))
    if np.std(model) == 0 or np.std(human) == 0:
        return float("nan"), rmse
    return float(np.corrcoef(model, human)[0, 1]), rmse


def least(values: np.ndarray) -> int:
    """Index of the least value; values within 1e-9 (relative) of it go to the first (smaller sigma)."""
    v = np.asarray(values, float)
    lo = np.nanmin(v)
    return int(np.flatnonzero(v <= lo + 1e-9 * max(1.0, abs(lo)))[0])


def best_sigma_index(M: np.ndarray, h: np.ndarray) -> int:
    """M (sigmas, scenes) model means, h (scenes,) human means: sigma of least RMSE."""
    return least(np.sqrt(np.mean((M - h[None]) ** 2, axis=1)))


def held_out_r(M: np.ndarray, h: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Leave-one-scene-out: for each scene, sigma chosen by RMSE on the others, that
    scene's prediction at it; (r, RMSE, chosen sigma index per scene)."""
    n = len(h)
    pred, chosen = np.empty(n), np.empty(n, int)
    for i in range(n):
        keep = np.arange(n) != i
        k = best_sigma_index(M[:, keep], h[keep])
        chosen[i], pred[i] = k, M[k, i]
    r, rmse = fit_stats(pred, h)
    return r, rmse, chosen


def bootstrap_sigma(M: np.ndarray, responses: np.ndarray, sigmas: np.ndarray, n_boot: int = 2000, seed: int = 0):
    """Percentile 95% interval of the best sigma when participants are resampled
    (responses: participants x scenes, complete)."""
    rng = np.random.default_rng(seed)
    P = responses.shape[0]
    out = np.empty(n_boot)
    for b in range(n_boot):
        h = responses[rng.integers(0, P, P)].mean(axis=0)
        out[b] = sigmas[best_sigma_index(M, h)]
    return float(np.percentile(out, 2.5)), float(np.percentile(out, 97.5))


def authors_reference(repo: Path, experiment: int, human: pd.Series) -> pd.DataFrame | None:
    """The authors' perceptual-noise model (levels 0-10) where the clone has it: per
    level, r and RMSE of their mean count against the human means."""
    folder = repo / "code" / "R" / "simulations" / f"exp{experiment}"
    rows = []
    for level in range(11):
        p = folder / f"perceptual,impulse-aligned,dynamics_{level},0,0.json"
        if not p.is_file():
            return None
        data = json.loads(p.read_text())
        m = np.array([np.mean([len(run) for run in data[f"trial_{t}"]]) for t in human.index])
        r, rmse = fit_stats(m, human.to_numpy())
        rows.append({"level": level, "sigma_authors": 0.03 * level, "r": r, "rmse": rmse, "means": m})
    return pd.DataFrame(rows)


def sigma_units(rule: str, sigma: float) -> dict:
    """The sigma in the authors' units and as fractions of the brick's width and height
    and of the edge along the perturbed axis (the paper's unit)."""
    w, h = BRICK_A
    if rule == "authors-x":
        return {"authors_units": sigma, "brick_widths": sigma / w, "brick_heights": sigma / h,
                "paper_unit_flat": sigma / w, "paper_unit_standing": sigma / h,
                "paper_unit_note": "x only: a fraction of the edge along x, which is the width for a flat brick "
                                   "and the height for a standing one"}
    return {"authors_units_flat_x": sigma * w, "authors_units_flat_z": sigma * h, "brick_widths_x": sigma,
            "paper_unit": sigma, "paper_unit_note": "the paper's rule: sigma is already a fraction of each edge"}


# ----------------------------------------------------------------------------- the whole check


def engine_rules(engine: str) -> tuple[str, ...]:
    """The noise rules `engine` can run: the authors' x-only rule in a 2-D world
    (box2dweb, box2d), the paper's 3-D rule too in a 3-D one."""
    return BOX2D_RULES if engine in ENGINES_2D else RULES


def analyse(repo, experiment: int, out, sigmas=DEFAULT_GRID, n_runs: int = 100, seed: int = 0, jobs: int = 2,
            rules=None, cache_dir=None, log=None, fixed: dict | None = None, engine: str = DEFAULT_ENGINE) -> dict:
    """The whole check (module docstring), in `engine` (the command's default, the
    authors' own Box2D) with `rules` (None: every rule the engine can run,
    `engine_rules`). `fixed` ({rule: sigma}, e.g. the best sigmas of another
    experiment's summary.json): r and RMSE at those sigmas too, the held-out test of
    a sigma chosen elsewhere."""
    rules = engine_rules(engine) if rules is None else tuple(rules)
    repo, out = Path(repo), Path(out)
    scenes = read_scenes(repo, experiment)  # bad input raises here, before anything is written
    pred = read_predictions(repo, experiment)
    answered = set(pred.trial)
    skipped = [{"trial": s.trial, "reason": "no human predictions"} for s in scenes if s.trial not in answered]
    scenes = [s for s in scenes if s.trial in answered]  # a scene nobody judged is reported, not fitted
    if not scenes:
        raise MentalJengaError(f"{repo}: no scene of experiment {experiment} has human predictions")
    trials = [s.trial for s in scenes]
    wide = pred[pred.trial.isin(trials)].pivot_table(index="participant", columns="trial", values="response", aggfunc="mean")[trials]
    complete = wide.dropna()
    human = wide.mean(axis=0)  # per scene, over every participant who answered it
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    runs, run_info = simulate_all(scenes, rules, sigmas, n_runs, seed, Path(cache_dir or out / "cache"), jobs, log, engine)
    wall = time.time() - t0
    label_of = {s.label: s.trial for s in scenes}
    runs["scene"] = runs["trial"].map(label_of)
    means = runs.groupby(["rule", "sigma", "scene"]).fallen.agg(["mean", "std"]).reset_index()
    sig = np.array(sorted(map(float, sigmas)))
    fit_rows, summary = [], {"experiment": experiment, "scenes_used": len(scenes), "scenes_skipped": len(skipped),
                             "skipped": skipped, "participants": int(wide.shape[0]), "runs_per_sigma": n_runs,
                             "seed": seed, "engine": engine, "linear_map": False, "rules": {}}
    for rule in rules:
        M = np.array([[means[(means.rule == rule) & (means.sigma == s) & (means.scene == t)]["mean"].iloc[0]
                       for t in trials] for s in sig])
        h = human.to_numpy()
        for k, s in enumerate(sig):
            r, rmse = fit_stats(M[k], h)
            fit_rows.append({"rule": rule, "engine": engine, "sigma": s, "r": r, "rmse": rmse})
        kb = best_sigma_index(M, h)
        r_best, rmse_best = fit_stats(M[kb], h)
        r_ho, rmse_ho, chosen = held_out_r(M, h)
        lo, hi = bootstrap_sigma(M, complete.to_numpy(), sig, seed=seed)
        rs = np.array([fit_stats(M[k], h)[0] for k in range(len(sig))])
        k_r = int(np.nanargmax(rs)) if np.isfinite(rs).any() else 0
        summary["rules"][rule] = {
            "best_sigma": float(sig[kb]), "best_sigma_interval_95": [lo, hi], "units": sigma_units(rule, float(sig[kb])),
            "interval_units": [sigma_units(rule, lo), sigma_units(rule, hi)],
            "r": r_best, "rmse": rmse_best, "held_out_r": r_ho, "held_out_rmse": rmse_ho,
            "held_out_sigmas": sorted({float(sig[c]) for c in chosen}),
            "best_r_sigma": float(sig[k_r]), "best_r": float(rs[k_r]),
            "deterministic_r_rmse": list(fit_stats(M[0], h)) if sig[0] == 0 else None,
        }
        summary["rules"][rule]["model_means"] = {int(t): float(v) for t, v in zip(trials, M[kb])}
        if fixed and rule in fixed:
            k = int(np.argmin(np.abs(sig - fixed[rule])))
            if not np.isclose(sig[k], fixed[rule]):
                raise MentalJengaError(f"the fixed sigma {fixed[rule]:g} of rule {rule} is not on the grid")
            r_f, rmse_f = fit_stats(M[k], h)
            summary["rules"][rule]["at_fixed_sigma"] = {"sigma": float(sig[k]), "r": r_f, "rmse": rmse_f}
    summary["human_means"] = {int(t): float(v) for t, v in human.items()}
    ref = authors_reference(repo, experiment, human)
    if ref is not None:
        kb = least(ref.rmse.to_numpy())
        summary["authors_perceptual"] = {"best_rmse_level": int(ref.level[kb]), "r": float(ref.r[kb]), "rmse": float(ref.rmse[kb]),
                                         "best_r": float(ref.r.max()), "best_r_level": int(ref.level[ref.r.idxmax()])}
    summary["timing"] = {"wall_s": round(wall, 1), "sim_cpu_s": round(run_info["cpu_s"], 1), **{k: run_info[k] for k in ("computed", "cached")},
                         "jobs": jobs, "load_before": os.getloadavg()[0]}
    fit = pd.DataFrame(fit_rows)
    fit.to_csv(out / "fit.csv", index=False)
    means.to_csv(out / "scenes.csv", index=False)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    scatter(out / "scatter.png", trials, human, summary, ref, experiment)
    return summary


def scatter(path: Path, trials, human: pd.Series, summary: dict, ref, experiment: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(rule, s) for rule, s in summary["rules"].items()]
    n = len(panels) + (ref is not None)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.2), squeeze=False)
    top = max(8.0, float(human.max()) + 1)
    h = human.to_numpy()
    for ax, (rule, s) in zip(axes[0], panels):
        m = np.array([s["model_means"][int(t)] for t in trials])
        ax.scatter(m, h, s=18, color="C0")
        ax.set_title(f"{rule} ({summary['engine']}): sigma {s['best_sigma']:g}\nr {s['r']:.2f}, RMSE {s['rmse']:.2f}, held-out r {s['held_out_r']:.2f}", fontsize=9)
    if ref is not None:
        a = summary["authors_perceptual"]
        m = ref.means[a["best_rmse_level"]]
        ax = axes[0][-1]
        ax.scatter(m, h, s=18, color="C3")
        ax.set_title(f"authors' perceptual model, level {a['best_rmse_level']}\nr {a['r']:.2f}, RMSE {a['rmse']:.2f}", fontsize=9)
    for ax in axes[0]:
        ax.plot([0, top], [0, top], color="0.7", lw=0.8)
        ax.set_xlim(-0.3, top)
        ax.set_ylim(-0.3, top)
        ax.set_xlabel("model: mean red bricks off the table")
        ax.set_ylabel("people: mean predicted count")
        ax.set_aspect("equal")
    fig.suptitle(f"Mental Jenga experiment {experiment}: {len(trials)} scenes, one point per scene", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m analysis.mental_jenga", description=__doc__.split("\n\n")[0])
    ap.add_argument("--repo", required=True)
    ap.add_argument("--experiment", type=int, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--sigmas", default=None, help="comma-separated grid (default 0, 0.01, ..., 0.30)")
    ap.add_argument("--rules", default=None, help=f"comma-separated noise rules (default {','.join(RULES)}; "
                    f"with --engine box2dweb or box2d, a 2-D world: {','.join(BOX2D_RULES)})")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--engine", default=DEFAULT_ENGINE,
                    help="box2dweb (default: the authors' exact engine, Box2D 2.1a in JavaScript, through node; "
                         "npm ci --prefix models/box2dweb), box2d (the same protocol in pybox2d, Box2D 2.3, the extra "
                         "`box2d`; both 2-D, the authors' world, and their rule is the authors' x-only noise), mujoco "
                         "or physx (the sapien package; these two also draw the paper's rule paper-3d, which "
                         "lgp.reproduce --sigma-from reads)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cache", default=None, help="cache folder (default OUT/cache)")
    ap.add_argument("--fixed", default=None, metavar="SUMMARY",
                    help="summary.json of another experiment: r and RMSE at its best sigmas too (the held-out test)")
    args = ap.parse_args(argv)
    try:
        sigmas = DEFAULT_GRID if args.sigmas is None else tuple(float(v) for v in args.sigmas.split(","))
        from models.counterfactual import WORLDS

        if args.engine not in WORLDS:
            raise MentalJengaError(f"unknown --engine {args.engine!r}; known: {', '.join(WORLDS)}")
        known = engine_rules(args.engine)
        rules = known if args.rules is None else tuple(args.rules.split(","))
        bad = [r for r in rules if r not in known]
        if args.engine == "box2d":
            from models.box2d_engine import import_box2d

            import_box2d()  # the one-line hint of the extra to install, before anything is written
        if args.engine == "box2dweb":
            from models.box2dweb_engine import node_command

            node_command()  # the one-line hint: node and npm ci --prefix models/box2dweb
        if bad or args.runs < 1 or any(not np.isfinite(s) or s < 0 for s in sigmas):
            raise MentalJengaError(f"--rules must be among {', '.join(known)} (engine {args.engine}), --runs >= 1, "
                                   "sigmas finite and >= 0")
        from lgp.owned import json_record, refuse_foreign_folder

        refuse_foreign_folder(Path(args.out), "summary.json", is_ours=json_record("rules", "human_means"))  # before the simulations, not after
        fixed = None
        if args.fixed:
            try:
                other = json.loads(Path(args.fixed).read_text())
                fixed = {rule: float(v["best_sigma"]) for rule, v in other["rules"].items()}
            except (OSError, ValueError, KeyError, TypeError) as e:
                raise MentalJengaError(f"{args.fixed}: not a summary.json of analysis.mental_jenga ({type(e).__name__}: {e})") from None
        s = analyse(args.repo, args.experiment, args.out, sigmas, args.runs, args.seed, args.jobs, rules, args.cache, fixed=fixed, engine=args.engine)
    except (MentalJengaError, ValueError, InputError) as e:
        print(f"analysis.mental_jenga: {e}", file=sys.stderr)
        return 2
    for rule, v in s["rules"].items():
        print(f"{rule}: best sigma {v['best_sigma']:g} [{v['best_sigma_interval_95'][0]:g}, {v['best_sigma_interval_95'][1]:g}], "
              f"r {v['r']:.3f}, RMSE {v['rmse']:.3f}, held-out r {v['held_out_r']:.3f}"
              + (f"; at the fixed sigma {v['at_fixed_sigma']['sigma']:g}: r {v['at_fixed_sigma']['r']:.3f}, "
                 f"RMSE {v['at_fixed_sigma']['rmse']:.3f}" if "at_fixed_sigma" in v else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())

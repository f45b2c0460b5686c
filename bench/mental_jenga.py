"""Mental Jenga facts the docs quote (docs/mental-jenga.md), measured on Experiment 2:

1. does the scaling change verdicts? deterministic counterfactual (black brick
   removed, no noise) per red brick at SCALE 0.1 against 0.2 (and with the authors'
   linear damping off);
2. how often do those verdicts agree with the authors' Box2D run (exp2_info `fall`)?
3. the "above" set the noise moves against the authors' feature `above` (+1: theirs
   counts the black brick);
4. speed, side by side in one process: the run loop as it was (`old_run` below, a
   copy of models.counterfactual before the exact speed-ups: stop only when every
   tree of the model sleeps, every run simulated) against the current one
   (stop once the bricks still on the scene all sleep; equal starts simulated once),
   on every scene at a few sigmas; whether each run's fallen bricks are the same;
   how many of the full grid's starts are distinct; and the projection to the
   issue's target (42 scenes x 31 sigmas x 100 runs on 2 cores).

    python bench/mental_jenga.py --repo /work/shared/mental-jenga/repo-exp2 [--runs 10] [--write]
    python bench/mental_jenga.py --box2d [--runs 5] [--fit DIR]

    python bench/mental_jenga.py --box2dweb [--runs 5] [--levels 8] [--seed-runs 100] [--write]

6. --box2dweb: the authors' exact engine (models/box2dweb_engine.py, box2dweb
   through Node): with the authors' seed (jenga.js `authors_seed`), run for run
   against their saved perceptual-noise runs at the --levels, with the early stop
   and without it; then CPU per run of box2dweb (Node's CPU counted: the children's
   rusage), pybox2d and MuJoCo side by side, the authors' rule at a few sigmas, the
   same normals, scene by scene interleaved, and the projection of the issue's grid.

5. --box2d: the authors' own engine (models/box2d_engine.py) against MuJoCo:
   deterministic verdicts against the authors' `fall` column and their level-0
   output, the carried set against their `above` feature, and CPU per run side by
   side (the authors' rule at a few sigmas, the same normals, scene by scene
   interleaved); with --fit DIR (an `analysis.mental_jenga --engine box2d` output of
   experiment 2) the mean count per scene at the authors' levels k (sigma 0.03 k)
   against their own perceptual-noise outputs at level k.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import machine, write_section  # noqa: E402
from lgp.command_times import cpu_seconds  # noqa: E402
from models.counterfactual import FallSettings, JengaWorld, Perturbation, counterfactual_runs, deterministic_falls, draw_normals  # noqa: E402
from models.risk.engine import CHECK_INTERVAL, REST_SLACK, REST_SPEED, REST_WINDOW, block_speeds  # noqa: E402
from stimuli.mental_jenga import read_info, read_scenes  # noqa: E402

SPEED_SIGMAS = (0.06, 0.15, 0.24)
GRID = tuple(round(0.01 * k, 2) for k in range(31))


def old_run(world: JengaWorld, p_WB: np.ndarray) -> np.ndarray:
    """JengaWorld.run as it was before the speed-ups (commit 738a001), kept here to
    time it side by side: it stops when every tree of the model sleeps, parked bricks
    included."""
    mj, m, d = world.mj, world.model, world.data
    mj.mj_resetData(m, d)
    world.qpos[:] = world.q_settled
    world.qpos[:, :3] = p_WB
    fallen = np.zeros(world.n, bool)
    active = ~world.black
    for i in np.flatnonzero(world.black):
        world._park(i)
    mj.mj_forward(m, d)
    fall_z = world.scene.fall_z
    rest_since, rest_speed = 0.0, np.inf
    n_checks = int(np.ceil(world.duration / CHECK_INTERVAL - 1e-9))
    for k in range(1, n_checks + 1):
        t = min(world.duration, k * CHECK_INTERVAL)
        world._step_to(t)
        below = active & (world.qpos[:, 2] < fall_z)
        if below.any():
            for i in np.flatnonzero(below):
                world._park(i)
            fallen |= below
            active &= ~below
            mj.mj_forward(m, d)
            rest_since, rest_speed = t, np.inf
            continue
        if not active.any() or int(d.ntree_awake) == 0:
            break
        speed = block_speeds(world.qvel[active, :3], world.qvel[active, 3:], world.radii[active])
        fastest = float(speed.max())
        if fastest >= REST_SPEED:
            rest_since, rest_speed = t, np.inf
        elif rest_speed == np.inf:
            rest_since, rest_speed = t, fastest
        elif t - rest_since >= REST_WINDOW - 1e-9:
            if fastest <= rest_speed + REST_SLACK:
                break
            rest_since, rest_speed = t, fastest
    return fallen


def speed(scenes, n_runs: int, rules=("paper-3d", "authors-x")) -> dict:
    """Old loop against new, per scene, interleaved (same process, same load)."""
    out = {"old_cpu": 0.0, "new_cpu": 0.0, "runs": 0, "new_simulated": 0, "same_ids": 0, "same_count": 0}
    for s in scenes:
        for rule in rules:
            world = JengaWorld(s)
            P = Perturbation(world)
            z = draw_normals(n_runs, world.n, 0, s.trial)
            starts = [P.positions(rule, sg, z) for sg in SPEED_SIGMAS]
            c0 = time.process_time()
            old = [old_run(world, p[r]) for p in starts for r in range(n_runs)]
            c1 = time.process_time()
            new = counterfactual_runs(s, rule, SPEED_SIGMAS, n_runs)
            c2 = time.process_time()
            out["old_cpu"] += c1 - c0
            out["new_cpu"] += c2 - c1
            out["runs"] += len(old)
            out["new_simulated"] += len({p[r].tobytes() for p in starts for r in range(n_runs)})
            names = [b.name for b in s.bricks]
            for f, (_, row) in zip(old, new.iterrows()):
                ids = " ".join(nm for nm, x in zip(names, f) if x)
                out["same_ids"] += int(ids == row["ids"])
                out["same_count"] += int(int(f.sum()) == row["fallen"])
    return out


def engine_agreement(scenes, human: dict, sigma: float, n_runs: int, engine: str = "physx") -> dict:
    """MuJoCo against `engine` on every scene: deterministic verdicts per red brick
    and counts per scene; then the paper's rule at `sigma` (n_runs, the same normals
    in both engines, each on its own settled scene): mean count per scene, r between
    the engines, and each engine's r and RMSE against the human means."""
    from analysis.mental_jenga import fit_stats

    out = {"red": 0, "same_verdict": 0, "same_count": 0, "counts": {"mujoco": [], engine: []},
           "means": {"mujoco": [], engine: []}, "cpu": {"mujoco": 0.0, engine: 0.0}, "h": []}
    for s in scenes:
        det = {}
        for e in ("mujoco", engine):
            c0 = time.process_time()
            det[e] = deterministic_falls(s, engine=e)
            runs = counterfactual_runs(s, "paper-3d", [sigma], n_runs, engine=e)
            out["cpu"][e] += time.process_time() - c0
            out["counts"][e].append(int(det[e].sum()))
            out["means"][e].append(float(runs.fallen.mean()))
        red = ~np.array([b.black for b in s.bricks])
        out["red"] += int(red.sum())
        out["same_verdict"] += int((det["mujoco"][red] == det[engine][red]).sum())
        out["same_count"] += int(det["mujoco"].sum() == det[engine].sum())
        out["h"].append(human[s.trial])
    h = np.array(out["h"])
    out["fit"] = {e: fit_stats(np.array(out["means"][e]), h) for e in ("mujoco", engine)}
    out["fit0"] = {e: fit_stats(np.array(out["counts"][e], float), h) for e in ("mujoco", engine)}
    out["r_counts"] = float(np.corrcoef(out["counts"]["mujoco"], out["counts"][engine])[0, 1])
    out["r_means"] = float(np.corrcoef(out["means"]["mujoco"], out["means"][engine])[0, 1])
    return out


def distinct_starts(scenes, n_runs: int = 100, rules=("paper-3d", "authors-x")) -> dict:
    """How many of the full grid's runs (31 sigmas x n_runs per scene and rule) start
    from distinct positions, i.e. are simulated."""
    out = {}
    for rule in rules:
        total = distinct = 0
        for s in scenes:
            world = JengaWorld(s)
            P = Perturbation(world)
            z = draw_normals(n_runs, world.n, 0, s.trial)
            keys = set()
            for sg in GRID:
                p = P.positions(rule, sg, z)
                keys.update(p[r].tobytes() for r in range(n_runs))
            total += len(GRID) * n_runs
            distinct += len(keys)
        out[rule] = (distinct, total)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[2] / "shared" / "mental-jenga" / "repo-exp2"),
                    help="a clone of cicl-stanford/mental_jenga (default: the shared copy of experiment 2 beside this clone, ../shared)")
    ap.add_argument("--write", action="store_true", help="write the section of docs/benchmarks.md")
    ap.add_argument("--runs", type=int, default=10, help="runs per sigma in the side-by-side timing")
    ap.add_argument("--engines", action="store_true", help="only MuJoCo against PhysX (its own section)")
    ap.add_argument("--variants", action="store_true",
                    help="only: faster MuJoCo settings (a change of the physics) against the measure's, run by run (own section)")
    ap.add_argument("--engine-sigma", type=float, default=0.18, help="the paper's rule's sigma for the engine comparison")
    ap.add_argument("--engine-runs", type=int, default=20)
    ap.add_argument("--box2d", action="store_true", help="only: Box2D (the authors' engine) against MuJoCo (printed)")
    ap.add_argument("--fit", default=None, help="an analysis.mental_jenga output folder of experiment 2 in a 2-D engine (box2dweb or box2d): its means at the authors' levels against theirs")
    ap.add_argument("--box2dweb", action="store_true",
                    help="only: box2dweb (the authors' exact engine) against their saved runs, and its speed beside "
                         "pybox2d and MuJoCo (own section with --write)")
    ap.add_argument("--levels", default="8", help="with --box2dweb: the authors' levels checked run for run")
    ap.add_argument("--seed-runs", type=int, default=100, help="with --box2dweb: runs per scene and level checked")
    args = ap.parse_args(argv)
    repo = Path(args.repo)
    load0 = machine()
    info = read_info(repo, 2)
    scenes = read_scenes(repo, 2)
    if args.engines:
        return engines_section(args, repo, scenes, load0)
    if args.variants:
        return variants_section(args, scenes, load0)
    if args.box2d:
        return box2d_section(args, repo, scenes, info, load0)
    if args.box2dweb:
        return box2dweb_section(args, repo, scenes, load0)
    if args.fit:
        print(levels_table(repo, Path(args.fit)))
        return 0
    big = {s.trial: s for s in read_scenes(repo, 2, scale=0.2)}
    feats = json.loads((repo / "code/R/data/features/black_exp2.json").read_text())
    n_red = agree_scale = agree_ref = agree_nodamp = agree_above = 0
    counts_ref, counts_mine = [], []
    for s in scenes:
        f = deterministic_falls(s)
        f2 = deterministic_falls(big[s.trial])
        f0 = deterministic_falls(s, FallSettings(damping=False))
        ref = info[info.trial == s.trial].set_index("index")["fall"]
        red = [k for k, b in enumerate(s.bricks) if not b.black]
        n_red += len(red)
        agree_scale += int(sum(f[k] == f2[k] for k in red))
        agree_ref += int(sum(int(f[k]) == ref.get(s.bricks[k].index, 0) for k in red))
        agree_nodamp += int(sum(int(f0[k]) == ref.get(s.bricks[k].index, 0) for k in red))
        counts_ref.append(int(sum(ref.get(s.bricks[k].index, 0) for k in red)))
        counts_mine.append(int(f.sum()))
        agree_above += int(Perturbation(JengaWorld(s)).above.sum() + 1 == feats[f"trial_{s.trial}"]["above"])
    same_count = int(sum(a == b for a, b in zip(counts_ref, counts_mine)))
    r_counts = float(np.corrcoef(counts_ref, counts_mine)[0, 1])
    t0 = time.time()
    sp = speed(scenes, args.runs)
    wall = time.time() - t0
    grid = distinct_starts(scenes)
    old_per_run = sp["old_cpu"] / sp["runs"]
    new_per_run = sp["new_cpu"] / sp["runs"]
    new_per_sim = sp["new_cpu"] / sp["new_simulated"]
    target = 42 * 31 * 100
    proj = {rule: d * new_per_sim for rule, (d, _) in grid.items()}
    text = f"""## Mental Jenga (bench/mental_jenga.py)

Machine at start: {load0}; at end: {machine()}.

| measure (experiment 2, 42 scenes, {n_red} red bricks) | value |
|---|---|
| deterministic verdicts per red brick, SCALE 0.1 vs 0.2 | {agree_scale}/{n_red} the same |
| deterministic verdicts vs the authors' Box2D run (exp2_info `fall`), damping on | {agree_ref}/{n_red} agree |
| the same, the authors' linear damping off | {agree_nodamp}/{n_red} agree |
| fallen count per scene equal to the authors' | {same_count}/42 scenes (r = {r_counts:.2f}) |
| bricks the noise moves ("above" set) = the authors' `above` feature - 1 | {agree_above}/42 scenes |

Speed, side by side in one process ({sp['runs']:,} runs: 42 scenes x 2 rules x sigma {", ".join(map(str, SPEED_SIGMAS))} x {args.runs} runs;
{wall:.0f} s wall): the run loop before the speed-ups (`old_run`) against `counterfactual_runs` now
(whose CPU also counts settling each scene and drawing its noise; the old loop's does not).

| measure | before | now |
|---|---|---|
| CPU per run | {old_per_run:.4f} s | {new_per_run:.4f} s (ratio before/now {old_per_run / new_per_run:.2f}) |
| runs simulated | {sp['runs']:,} | {sp['new_simulated']:,} (equal starts once) |
| CPU per simulated run | {old_per_run:.4f} s | {new_per_sim:.4f} s (ratio {old_per_run / new_per_sim:.2f}) |
| runs whose fallen bricks are the same bricks as before | | {sp['same_ids']:,}/{sp['runs']:,} (counts: {sp['same_count']:,}) |
| full grid 42 x 31 x 100 = {target:,} runs per rule: distinct starts | | paper-3d {grid['paper-3d'][0]:,}, authors-x {grid['authors-x'][0]:,} |
| projected CPU for the full grid, one rule (paper-3d) | {target * old_per_run / 60:.0f} min | {proj['paper-3d'] / 60:.0f} min ({proj['paper-3d'] / 120:.0f} min per core of 2; target: 3 min on 2 cores) |
"""
    print(text)
    if args.write:
        write_section(Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md", "Mental Jenga (bench/mental_jenga.py)", text)
    return 0


#: MuJoCo settings that would make a run cheaper, each a change of the physics: (label, model.opt field, value).
VARIANTS = (("sleep tolerance 3e-3 (measure: 1e-3)", "sleep_tolerance", 3e-3),
            ("solver tolerance 1e-6 (measure: 1e-8)", "tolerance", 1e-6))
#: (The CG and PGS solvers were 2.5 and 5.5 times slower than Newton on these scenes in a first trial: not listed.)


def variants_section(args, scenes, load0: str, sigma: float = 0.15) -> int:
    """Each variant against the measure's settings on every scene, the same starts
    (paper's rule at `sigma`, args.runs runs): CPU ratio and runs with the same count."""
    cpu = np.zeros(len(VARIANTS) + 1)
    same = np.zeros(len(VARIANTS), int)
    mean = np.zeros(len(VARIANTS) + 1)
    n = 0
    t0 = time.time()
    for s in scenes:
        worlds = []
        for k in range(len(VARIANTS) + 1):
            w = JengaWorld(s)
            if k:
                _, field, value = VARIANTS[k - 1]
                setattr(w.model.opt, field, value)
                w.q_settled = w._presettle()
            worlds.append(w)
        P = Perturbation(worlds[0]).positions("paper-3d", sigma, draw_normals(args.runs, worlds[0].n, 0, s.trial))
        for r in range(args.runs):
            counts = []
            for k, w in enumerate(worlds):  # interleaved: the same load for every setting
                c0 = time.process_time()
                counts.append(int(w.run(P[r]).sum()))
                cpu[k] += time.process_time() - c0
            same += np.array(counts[1:]) == counts[0]
            mean += counts
            n += 1
    rows = "\n".join(f"| {label} | {cpu[0] / cpu[k + 1]:.2f} | {same[k]}/{n} | {mean[k + 1] / n:.2f} |"
                     for k, (label, _, _) in enumerate(VARIANTS))
    text = f"""## Mental Jenga engine settings (bench/mental_jenga.py --variants)

Machine at start: {load0}; at end: {machine()}. {time.time() - t0:.0f} s wall.
Cheaper MuJoCo settings, each a change of the physics, against the measure's own, on
the same {n} starts (42 scenes x {args.runs} runs, the paper's rule at {sigma:g} d, the
scene settled under each setting); CPU per run as a ratio (measure / variant, > 1:
the variant is faster), interleaved run by run.

| setting | CPU ratio | runs with the same count | mean count (measure's: {mean[0] / n:.2f}) |
|---|---|---|---|
{rows}
"""
    print(text)
    if args.write:
        write_section(Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md",
                      "Mental Jenga engine settings (bench/mental_jenga.py --variants)", text)
    return 0


def engines_section(args, repo: Path, scenes, load0: str) -> int:
    from stimuli.mental_jenga import read_predictions

    pred = read_predictions(repo, 2)
    human = pred.groupby("trial").response.mean().to_dict()
    t0 = time.time()
    a = engine_agreement(scenes, human, args.engine_sigma, args.engine_runs)
    wall = time.time() - t0
    sg, n = args.engine_sigma, args.engine_runs
    text = f"""## Mental Jenga engines (bench/mental_jenga.py --engines)

Machine at start: {load0}; at end: {machine()}. {wall:.0f} s wall.
MuJoCo (the measure's settings) against PhysX 5 (sapien, the risk engine's faithful
profile: 1 ms steps, TGS 20 position iterations, 2 mm contact offset), each scene
settled in each engine; noisy runs: the paper's rule at {sg:g} d, {n} runs per scene,
the same normals in both engines.

| measure (experiment 2, 42 scenes, {a['red']} red bricks) | MuJoCo | PhysX |
|---|---|---|
| deterministic verdicts per red brick, PhysX = MuJoCo | {a['same_verdict']}/{a['red']} | |
| deterministic count per scene equal | {a['same_count']}/42 (r = {a['r_counts']:.2f}) | |
| deterministic count vs people: r, RMSE | {a['fit0']['mujoco'][0]:.2f}, {a['fit0']['mujoco'][1]:.2f} | {a['fit0']['physx'][0]:.2f}, {a['fit0']['physx'][1]:.2f} |
| mean count at {sg:g} d vs people: r, RMSE | {a['fit']['mujoco'][0]:.2f}, {a['fit']['mujoco'][1]:.2f} | {a['fit']['physx'][0]:.2f}, {a['fit']['physx'][1]:.2f} |
| r between the engines' mean counts at {sg:g} d | {a['r_means']:.2f} | |
| CPU (deterministic + {n} runs per scene, with settling) | {a['cpu']['mujoco']:.0f} s | {a['cpu']['physx']:.0f} s |
"""
    print(text)
    if args.write:
        write_section(Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md",
                      "Mental Jenga engines (bench/mental_jenga.py --engines)", text)
    return 0


def levels_table(repo: Path, fit: Path) -> str:
    """The mean count per scene of an `analysis.mental_jenga --engine box2d` run of
    experiment 2 (fit/scenes.csv) at the authors' levels k (sigma 0.03 k) against their
    own perceptual-noise outputs at level k, and each against the human means."""
    import pandas as pd

    from analysis.mental_jenga import fit_stats
    from stimuli.mental_jenga import read_predictions

    sims = repo / "code/R/simulations/exp2"
    human = read_predictions(repo, 2).groupby("trial").response.mean()
    means = pd.read_csv(fit / "scenes.csv")
    means = means[means.rule == "authors-x"]
    trials = sorted(human.index)
    rows = []
    for level in range(11):
        data = json.loads((sims / f"perceptual,impulse-aligned,dynamics_{level},0,0.json").read_text())
        theirs = np.array([np.mean([len(r) for r in data[f"trial_{t}"]]) for t in trials])
        m = means[np.isclose(means.sigma, 0.03 * level)].set_index("scene")["mean"]
        ours = np.array([m[t] for t in trials])
        h = human[trials].to_numpy()
        r_eng = float(np.corrcoef(ours, theirs)[0, 1]) if np.std(ours) and np.std(theirs) else float("nan")
        (r1, e1), (r2, e2) = fit_stats(ours, h), fit_stats(theirs, h)
        rows.append(f"| {level} ({0.03 * level:.2f}) | {r_eng:.2f} | {np.mean(np.abs(ours - theirs)):.2f} | "
                    f"{r1:.2f}, {e1:.2f} | {r2:.2f}, {e2:.2f} |")
    return (f"Mean count per scene at the authors' perceptual-noise levels ({fit}: Box2D here; theirs: 200 runs, "
            "code/R/simulations/exp2), and each against the human means (r, RMSE, no linear map):\n\n"
            "| level (sigma) | r ours vs theirs | mean abs. difference | ours vs people | theirs vs people |\n"
            "|---|---|---|---|---|\n" + "\n".join(rows) + "\n")


def box2d_section(args, repo: Path, scenes, info, load0: str) -> int:
    from models.box2d_engine import Box2DJengaWorld

    feats = json.loads((repo / "code/R/data/features/black_exp2.json").read_text())
    sims = repo / "code/R/simulations/exp2"
    ref0 = json.loads((sims / "perceptual,impulse-aligned,dynamics_0,0,0.json").read_text())
    n_red, agree = 0, {"box2d": 0, "mujoco": 0}
    same_ids = {"box2d": 0, "mujoco": 0}
    above = 0
    cpu = {"box2d": 0.0, "mujoco": 0.0}
    runs = {"box2d": 0, "mujoco": 0}
    t0 = time.time()
    for s in scenes:
        ref = info[info.trial == s.trial].set_index("index")["fall"]
        red = [k for k, b in enumerate(s.bricks) if not b.black]
        n_red += len(red)
        for e in ("box2d", "mujoco"):
            f = deterministic_falls(s, engine=e)
            agree[e] += int(sum(int(f[k]) == ref.get(s.bricks[k].index, 0) for k in red))
            mine = sorted(s.bricks[k].index for k in red if f[k])
            same_ids[e] += int(mine == sorted(ref0[f"trial_{s.trial}"][0]))
        above += int(Box2DJengaWorld(s).carried.sum() + 1 == feats[f"trial_{s.trial}"]["above"])
        for e in ("box2d", "mujoco"):  # interleaved scene by scene: the same load for both engines
            c0 = time.process_time()
            counterfactual_runs(s, "authors-x", SPEED_SIGMAS, args.runs, engine=e)
            cpu[e] += time.process_time() - c0
            runs[e] += len(SPEED_SIGMAS) * args.runs
    wall = time.time() - t0
    per = {e: cpu[e] / runs[e] for e in cpu}
    target = 42 * 30 * 100 + 42  # sigma 0: one run per scene (equal starts once)
    text = f"""## Mental Jenga: Box2D, the authors' engine, against MuJoCo (bench/mental_jenga.py --box2d)

Machine at start: {load0}; at end: {machine()}. {wall:.0f} s wall.

| measure (experiment 2, 42 scenes, {n_red} red bricks) | Box2D | MuJoCo |
|---|---|---|
| deterministic verdicts = the authors' `fall` column | {agree['box2d']}/{n_red} | {agree['mujoco']}/{n_red} |
| fallen bricks (ids) = the authors' level-0 output, scenes | {same_ids['box2d']}/42 | {same_ids['mujoco']}/42 |
| bricks the black one carries + 1 = the authors' `above` feature, scenes | {above}/42 | |
| CPU per run, the authors' rule at sigma {", ".join(map(str, SPEED_SIGMAS))}, {args.runs} runs (with settling) | {per['box2d'] * 1000:.1f} ms | {per['mujoco'] * 1000:.1f} ms |
| ratio MuJoCo / Box2D | {per['mujoco'] / per['box2d']:.1f} | |
| projected CPU, full grid (42 x 31 x 100; sigma 0 once per scene) | {target * per['box2d'] / 60:.1f} min ({target * per['box2d'] / 120:.1f} min on 2 cores) | {target * per['mujoco'] / 60:.0f} min |
"""
    if args.fit:
        text += "\n" + levels_table(repo, Path(args.fit))
    print(text)
    return 0


def authors_seed_check(repo: Path, scenes, levels, n_runs: int, early_stop: bool) -> dict:
    """box2dweb with the authors' seed against their saved runs: runs identical brick
    for brick, per level; one Node process per scene; CPU and Box2D steps per run."""
    from models.box2dweb_engine import Box2DWebJengaWorld, run_batch

    sims = repo / "code/R/simulations/exp2"
    saved = {k: json.loads((sims / f"perceptual,impulse-aligned,dynamics_{k},0,0.json").read_text()) for k in levels}
    out = {"runs": 0, "same": 0, "steps": 0, "differ": set()}
    c0 = cpu_seconds()
    for s in scenes:
        w = Box2DWebJengaWorld(s)
        (res,) = run_batch([w._scene(authors_seed={"levels": list(levels), "runs": n_runs})], early_stop)
        out["steps"] += res["steps"]
        for i, k in enumerate(levels):
            mine = res["fallen"][i * n_runs:(i + 1) * n_runs]
            theirs = saved[k][f"trial_{s.trial}"][:n_runs]
            same = sum(sorted(a) == sorted(b) for a, b in zip(mine, theirs))
            out["runs"] += n_runs
            out["same"] += same
            if same < n_runs:
                out["differ"].add(s.trial)
    out["cpu"] = cpu_seconds() - c0
    return out


def box2dweb_section(args, repo: Path, scenes, load0: str) -> int:
    levels = [int(k) for k in args.levels.split(",")]
    t0 = time.time()
    check = {stop: authors_seed_check(repo, scenes, levels, args.seed_runs, stop) for stop in (True, False)}
    from models.box2d_engine import Box2DNoise
    from models.box2dweb_engine import Box2DWebJengaWorld, run_batch

    engines = ("box2dweb", "box2d", "mujoco")
    cpu = dict.fromkeys(engines, 0.0)
    n = len(scenes) * len(SPEED_SIGMAS) * args.runs
    # box2dweb as the analysis runs it, a Node process with thousands of starts (there: one per scene,
    # 3,001 starts; here: every scene's starts, 42 x 3 x runs, in one process), the same normals
    batch, worlds = [], []
    c0 = cpu_seconds()
    for s in scenes:
        w = Box2DWebJengaWorld(s)
        z = draw_normals(args.runs, w.n, 0, s.trial)
        batch.append(w.batch([p for sg in SPEED_SIGMAS for p in Box2DNoise(w).positions("authors-x", sg, z)]))
        worlds.append(w)
    run_batch(batch)  # timed only: the runs themselves are the analysis's
    cpu["box2dweb"] = cpu_seconds() - c0
    c0 = cpu_seconds()
    for w in worlds[:5]:  # the fixed cost of a process: Node's start, loading box2dweb, V8's warm-up
        w.run()
    fixed = (cpu_seconds() - c0) / 5
    for s in scenes:  # the other engines scene by scene
        for e in engines[1:]:
            c0 = cpu_seconds()
            counterfactual_runs(s, "authors-x", SPEED_SIGMAS, args.runs, engine=e)
            cpu[e] += cpu_seconds() - c0
    wall = time.time() - t0
    per = {e: cpu[e] / n for e in engines}
    marginal = (cpu["box2dweb"] - fixed) / (n - 1)
    target = 42 * 30 * 100 + 42  # sigma 0: one run per scene (equal starts once)
    proj = {e: target * per[e] for e in engines}
    proj["box2dweb"] = 42 * fixed + (target - 42) * marginal  # the analysis: one process per scene
    on, off = check[True], check[False]
    text = f"""## Mental Jenga: box2dweb, the authors' exact engine (bench/mental_jenga.py --box2dweb)

Machine at start: {load0}; at end: {machine()}. {wall:.0f} s wall. Node's CPU is counted (children's rusage;
it includes V8's garbage-collector and compiler threads).

The authors' seed (jenga.js `authors_seed`: seedrandom(0) per scene and level, their gaussian and draw
order) against their saved perceptual-noise runs (code/R/simulations/exp2), level {", ".join(map(str, levels))},
the first {args.seed_runs} runs of each of the {len(scenes)} scenes; one Node process per scene:

| run | runs identical to theirs, brick for brick | Box2D steps per run after the removal | CPU per run (with each process's start) |
|---|---|---|---|
| early stop (once a step leaves every brick asleep and unmoved) | {on['same']:,}/{on['runs']:,} | {on['steps'] / on['runs']:.0f} | {1000 * on['cpu'] / on['runs']:.1f} ms |
| every one of the 700 steps (their loop) | {off['same']:,}/{off['runs']:,} | {off['steps'] / off['runs']:.0f} | {1000 * off['cpu'] / off['runs']:.1f} ms |

{"Scenes with a differing run: " + ", ".join(map(str, sorted(on["differ"] | off["differ"]))) if on["differ"] | off["differ"] else "No run differs."}

CPU per run side by side ({n:,} runs per engine: {len(scenes)} scenes x the authors' rule at sigma
{", ".join(map(str, SPEED_SIGMAS))} x {args.runs} runs, the same normals; each with its settling and noise). box2dweb
ran them in one Node process ({n:,} starts; the analysis gives each process a scene's 3,001), then pybox2d
and MuJoCo scene by scene. A Node process that runs one start costs {fixed:.2f} s of CPU (Node's start,
loading box2dweb, V8's warm-up; the mean of 5 scenes). The projection of the issue's grid (42 x 31 x 100;
sigma 0 once per scene: 126,042 starts) counts for box2dweb 42 such processes and the rest of its CPU
per start here; for the others, their CPU per run here.

| engine | CPU per run here | ratio to box2dweb | projected full grid, CPU | on 2 cores |
|---|---|---|---|---|
""" + "\n".join(f"| {e} | {per[e] * 1000:.1f} ms | {per[e] / per['box2dweb']:.2f} | {proj[e] / 60:.0f} min | "
                f"{proj[e] / 120:.1f} min |" for e in engines) + "\n"
    print(text)
    if args.write:
        write_section(Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md",
                      "Mental Jenga: box2dweb, the authors' exact engine (bench/mental_jenga.py --box2dweb)", text)
    return 0


if __name__ == "__main__":
    from lgp.cli import run_cli

    sys.exit(run_cli(main, prog="bench/mental_jenga.py"))

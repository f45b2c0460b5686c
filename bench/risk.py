"""Benchmark of the physical-risk simulations; writes the "risk" section of
docs/benchmarks.md (other sections are kept).

    python bench/risk.py [--drake-runs 20] [--mujoco-runs 200] [--no-grid] [--out docs/benchmarks.md]
    python bench/risk.py --physx [--physx-runs 100]    # only the "risk: physx" section


Measures, in one process, runs per second of each engine on a 10-block tower and
a 10-block line at the paper's sigma = 0.065 d (engines interleaved, so load from
other processes hits both alike), and the wall time of the paper's full grid
(24 trials x 11 sigma values x 100 runs = 26,400 runs): measured for MuJoCo over
all cores, projected for Drake from a sample of the same grid.
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, write_section  # noqa: E402
from models.risk import SIGMA_GRID, draw_normals, get_engine, perturb_from_normals, risk_table  # noqa: E402
from lgp.executor import default_jobs as _default_jobs  # noqa: E402
from models.risk.core import check_stable  # noqa: E402
from models.risk.structures import line, tower  # noqa: E402

SIGMA = 0.065
GRID_RUNS = 24 * len(SIGMA_GRID) * 100


def per_run_seconds(engine: str, scene, n: int, seed: int = 0, rounds: int = 1) -> tuple[float, float]:
    """Mean wall seconds per noisy run (model already built) and mean simulated time."""
    eng = get_engine(engine)
    check_stable(scene, engine)  # builds the model for this layout
    z = draw_normals(n, len(scene), seed)
    scenes = [perturb_from_normals(scene, SIGMA, zi) for zi in z]
    t0 = time.perf_counter()
    sim = [eng.simulate(s).sim_time for s in scenes]
    return (time.perf_counter() - t0) / n, float(np.mean(sim))


def grid_sample_seconds(engine: str, per_trial: int) -> float:
    """Mean wall seconds per run over a sample of the paper's grid (every trial,
    the lowest, middle and highest sigma), one process."""
    import stimuli

    trials = stimuli.load_paper()
    for t in trials:
        check_stable(t.target, engine)
    t0 = time.perf_counter()
    table = risk_table(trials, [SIGMA_GRID[0], SIGMA_GRID[5], SIGMA_GRID[-1]], n_sims=per_trial, seed=1, model=engine, jobs=1)
    return (time.perf_counter() - t0) / (len(table) * per_trial)


def measured_grid_seconds(engine: str, jobs: int) -> float:
    import stimuli

    t0 = time.perf_counter()
    risk_table(stimuli.load_paper(), SIGMA_GRID, n_sims=100, seed=0, model=engine, jobs=jobs)
    return time.perf_counter() - t0


def physx_section(n: int) -> str:
    """PhysX (both profiles) beside MuJoCo, per noisy run, interleaved in one process."""
    import stimuli

    load_before = machine()
    scenes = [tower(10), line(10), stimuli.load_trial("4H").target, stimuli.load_trial("7H").target]
    engines = ["mujoco", "physx", "physx:game-defaults"]
    rows = []
    for scene in scenes:
        res = {}
        for rnd in range(2):  # interleave the engines twice; keep the faster round of each
            for engine in engines:
                res.setdefault(engine, []).append(per_run_seconds(engine, scene, max(1, n // 2), seed=rnd))
        for engine in engines:
            s, sim = min(res[engine])
            rows.append((scene.label, engine, s, sim, s / min(res["mujoco"])[0]))
        print(rows[-3:], flush=True)
    lines = [
        "## risk: physx",
        "",
        "PhysX (`models/risk/physx_engine.py`, through sapien, CPU) beside MuJoCo: `python bench/risk.py --physx "
        f"--physx-runs {n}`. Noisy runs at sigma = {SIGMA} d with early termination, {n} runs per engine and scene "
        "in two interleaved rounds in one process (the faster round kept), so load from other processes hits "
        "every engine alike. PhysX builds a fresh scene per run (docs/risk.md, \"PhysX\"); that is included. "
        f"Machine: {load_before} at the start; {machine()} at the end: a loaded shared machine, so absolute times "
        "are noisy and the ratios are the number to read.",
        "",
        "| scene | engine | ms / run | mean simulated time (s) | time / MuJoCo's |",
        "|---|---|---|---|---|",
    ]
    for label, engine, s, sim, ratio in rows:
        shown = engine + (" (UNFAITHFUL)" if engine == "physx:game-defaults" else "")
        lines.append(f"| {label} | {shown} | {1000 * s:.1f} | {sim:.2f} | {ratio:.1f}x |")
    faithful = [r[4] for r in rows if r[1] == "physx"]
    lines += ["", f"PhysX faithful / MuJoCo time per run: {min(faithful):.1f}x to {max(faithful):.1f}x over these scenes; "
              "MuJoCo stays the default engine (it passes the faithfulness suite and is the fastest that does)."]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--physx", action="store_true", help="only the PhysX-beside-MuJoCo section")
    p.add_argument("--physx-runs", type=int, default=100)
    p.add_argument("--mujoco-runs", type=int, default=200)
    p.add_argument("--drake-runs", type=int, default=20)
    p.add_argument("--grid-sample", type=int, default=2, help="Drake runs per (trial, sigma) in the grid sample")
    p.add_argument("--no-grid", action="store_true", help="skip the full MuJoCo grid and the Drake grid sample")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    args = p.parse_args(argv)
    if args.physx:
        write_section(args.out, "risk: physx", physx_section(args.physx_runs))
        print(f"wrote the 'risk: physx' section of {args.out}")
        return 0

    jobs = _default_jobs()
    runs = {"mujoco": args.mujoco_runs, "drake": args.drake_runs}
    rows = []
    for scene in (tower(10), line(10)):
        res = {}
        for rnd in range(2):  # interleave the engines twice; keep the faster round of each
            for engine in ("mujoco", "drake"):
                s, sim = per_run_seconds(engine, scene, max(1, runs[engine] // 2), seed=rnd)
                res.setdefault(engine, []).append((s, sim))
        for engine, vals in res.items():
            s, sim = min(vals)
            rows.append((scene.label, engine, s, sim))
        print(rows[-2:], flush=True)

    lines = [
        "## risk",
        "",
        "Physical-risk simulations (`models/risk`, `python bench/risk.py`). "
        f"Machine: {os.cpu_count()} cores ({jobs} usable), {platform.processor() or platform.machine()}, "
        f"shared with other jobs, so absolute numbers are noisy; engines were run interleaved in one process.",
        "",
        f"Noisy runs at sigma = {SIGMA} d, early termination on (MuJoCo also sleeps resting bodies), "
        "model built once per layout and reused:",
        "",
        "| scene | engine | runs / s (1 process) | ms / run | mean simulated time (s) |",
        "|---|---|---|---|---|",
    ]
    for label, engine, s, sim in rows:
        lines.append(f"| {label} | {engine} | {1 / s:.1f} | {1000 * s:.1f} | {sim:.2f} |")
    ratio = {label: dict((e, s) for lb, e, s, _ in rows if lb == label) for label, *_ in rows}
    lines += ["", "Drake / MuJoCo time per run: " + ", ".join(
        f"{label} {r['drake'] / r['mujoco']:.0f}x" for label, r in ratio.items()) + "."]

    if not args.no_grid:
        wall = measured_grid_seconds("mujoco", jobs)
        print("mujoco grid", wall, flush=True)
        drake_s = grid_sample_seconds("drake", args.grid_sample)
        mj_s = grid_sample_seconds("mujoco", 20)
        print("drake sample", drake_s, "mujoco sample", mj_s, flush=True)
        lines += [
            "",
            f"Paper's full grid (24 trials x {len(SIGMA_GRID)} sigma values x 100 runs = {GRID_RUNS:,} runs), "
            f"goal < 6 min on 2 cores:",
            "",
            "| engine | how | wall time |",
            "|---|---|---|",
            f"| mujoco | measured, `risk_table(stimuli.load_paper(), SIGMA_GRID, n_sims=100, jobs={jobs})` | "
            f"{wall:.0f} s ({wall / 60:.1f} min) |",
            f"| mujoco | projected from a 1-process sample ({1000 * mj_s:.1f} ms/run) / {jobs} cores | "
            f"{GRID_RUNS * mj_s / jobs / 60:.1f} min |",
            f"| drake | projected from a 1-process sample ({args.grid_sample} run(s) per trial at sigma "
            f"{SIGMA_GRID[0]}, {SIGMA_GRID[5]}, {SIGMA_GRID[-1]}: {1000 * drake_s:.0f} ms/run) / {jobs} cores | "
            f"{GRID_RUNS * drake_s / jobs / 60:.0f} min |",
        ]
    write_section(args.out, "risk", "\n".join(lines))
    print(f"wrote the risk section of {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

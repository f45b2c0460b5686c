"""Benchmark of the search (lgp.search) against the paper's pipeline (lgp.planner.plan).

    python bench/search.py                 # writes the "search" section of docs/benchmarks.md
    python bench/search.py --samples 1     # fewer layouts per paper trial

1. The paper's 24 trials, layouts 0 .. samples-1 of seed 0: per layout the paper
   planner and then the search (default Budget) on the same layout, one after the
   other in this process, so their CPU-time ratio is comparable on a busy machine.
2. Rearrangement tasks (REV, SWAP, 20 from `stimuli.generate --kind rearrange`):
   the search's CPU and wall time per task, on one core (BLAS threads 1).
3. Where the search's time goes: the share in lgp.planner.plan_symbolic (IK
   seeding + KOMO) against the symbolic levels (bound, IK of keyframes).
4. The set-aside spots: the search's plan against the same skeleton with every
   set-aside spot replaced by a random candidate spot (the choice KOMO would have
   to make if it optimised a free table pose), and the time to rank the spots.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: before numpy loads

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import stimuli  # noqa: E402
from bench.common import machine, write_section  # noqa: E402
from lgp.planner import plan, plan_symbolic  # noqa: E402
from lgp.search import candidate_spots, first_sweep, kinetic_energy, search  # noqa: E402
from lgp.search.problem import Problem  # noqa: E402
from lgp.symbolic import Place, PlanState, SymbolicPlan, apply  # noqa: E402
from models.effort import sample_rng  # noqa: E402

REARRANGE = ROOT / "stimuli" / "rearrange"


def cpu_wall(f):
    c, w = time.process_time(), time.perf_counter()
    out = f()
    return out, time.process_time() - c, time.perf_counter() - w


def paper_side_by_side(samples: int):
    rows = []
    for trial in stimuli.load_paper():
        for sample in range(samples if trial.initial.is_random else 1):
            rng = sample_rng(0, sample)
            A = trial.sample_initial(rng)
            p, cpu_p, _ = cpu_wall(lambda: plan(A, trial.target, rng))
            rng = sample_rng(0, sample)
            A = trial.sample_initial(rng)
            r, cpu_s, _ = cpu_wall(lambda: search(A, trial.target, rng))
            rows.append((trial.id, sample, kinetic_energy(p), r.effort, cpu_p, cpu_s, r.komo_seconds, r.seconds, r.solves))
            print(f"{trial.id:>4} {sample}: paper {cpu_p:6.2f} s  search {cpu_s:6.2f} s  x{cpu_s / cpu_p:4.1f}  "
                  f"effort {rows[-1][2]:.4f} -> {r.effort:.4f}", flush=True)
    return rows


def rearrangements():
    tasks = [stimuli.load_file(REARRANGE / f"{n}.yaml") for n in ("REV", "SWAP")]
    with tempfile.TemporaryDirectory() as tmp:
        from stimuli.generate import generate

        tasks += [stimuli.load_file(p) for p in generate(tmp, 20, seed=0, kind="rearrange")]
    rows = []
    for trial in tasks:
        A = trial.sample_initial(np.random.default_rng(0))
        r, cpu, wall = cpu_wall(lambda: search(A, trial.target))
        rows.append((trial.id, len(A), r.set_asides, cpu, wall, r.komo_seconds, r.effort, r.gap))
        print(f"{trial.id:>5}: {len(A)} blocks, {r.set_asides} set-asides, {cpu:.2f} s CPU, {wall:.2f} s wall", flush=True)
    return rows


def random_spots(name: str, draws: int = 5):
    """The search's plan of task `name` against `draws` plans of the same skeleton
    whose set-aside spots are drawn at random from the candidates."""
    trial = stimuli.load_file(REARRANGE / f"{name}.yaml")
    A = trial.sample_initial(np.random.default_rng(0))
    r = search(A, trial.target)
    from lgp.planner import default_arm

    problem = Problem(A, trial.target, 0.05, 20, default_arm())
    rng = np.random.default_rng(1)
    efforts, rank_times = [], []
    for _ in range(draws):
        state, actions = PlanState(A), []
        for a in r.symbolic.actions:
            if isinstance(a, Place) and a.onto == ("table",) and not any(np.allclose(a.p_WB, s.p_WB) for s in trial.target.blocks):
                block = A.names.index(a.block)
                scene = state.scene.with_blocks(b for b in state.scene.blocks)
                t0 = time.perf_counter()
                spots = candidate_spots(problem, scene, block, list(range(len(trial.target.blocks))))
                rank_times.append(time.perf_counter() - t0)
                _, p = spots[int(rng.integers(len(spots)))]
                a = Place(a.block, a.onto, p, 0.0)
            state = apply(a, state)
            actions.append(a)
        symbolic = SymbolicPlan(A, trial.target, r.symbolic.assignment, tuple(actions))
        try:
            p = plan_symbolic(symbolic, 0)
            efforts.append(np.nan if first_sweep(p) else kinetic_energy(p))
        except Exception:
            efforts.append(np.nan)
    return r.effort, efforts, float(np.median(rank_times))


def profile(trial, top: int = 8) -> list[str]:
    """cProfile of one search (layout 0 of seed 0): the project's functions by cumulative time."""
    import cProfile
    import io
    import pstats

    rng = sample_rng(0, 0)
    A = trial.sample_initial(rng)
    search(A, trial.target, rng)  # warm (arm loaded, imports done)
    rng = sample_rng(0, 0)
    A = trial.sample_initial(rng)
    prof = cProfile.Profile()
    prof.enable()
    search(A, trial.target, rng)
    prof.disable()
    stats = pstats.Stats(prof, stream=io.StringIO())
    total = stats.total_tt
    rows = []
    for (path, line, name), (_, _, _, cum, _) in stats.stats.items():
        if "/lgp/" in path and name not in ("<module>",):
            rows.append((cum, f"{Path(path).parent.name}/{Path(path).name}:{name}"))
    rows.sort(reverse=True)
    return [f"{where} {cum:.3f} s ({100 * cum / total:.0f} %)" for cum, where in rows[:top]]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2, help="layouts per paper trial (default 2)")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    args = ap.parse_args(argv)
    start = machine()
    paper = paper_side_by_side(args.samples)
    rear = rearrangements()
    spots = {n: random_spots(n) for n in ("REV", "SWAP")}
    profiles = {t: profile(stimuli.load_trial(t)) for t in ("3E", "12E")}
    end = machine()
    cpu_model = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?")

    cp, cs = sum(r[4] for r in paper), sum(r[5] for r in paper)
    per_trial = {}
    for r in paper:
        a, b = per_trial.get(r[0], (0.0, 0.0))
        per_trial[r[0]] = (a + r[4], b + r[5])
    ratios = {t: b / a for t, (a, b) in per_trial.items()}
    worst = max(ratios, key=ratios.get)
    komo_share = sum(r[6] for r in paper) / sum(r[7] for r in paper)
    never_worse = all(r[3] <= r[2] for r in paper)
    lines = [
        "## search",
        "",
        f"`python bench/search.py --samples {args.samples}` ({cpu_model}; {start} at the start, {end} at the end; "
        "the machine is shared, so absolute seconds are noisy; ratios are measured side by side in one process).",
        "",
        f"**Paper's 24 trials, layouts 0-{args.samples - 1} of seed 0** ({len(paper)} layouts; a trial whose A is fixed "
        f"has one): the paper planner took {cp:.1f} s of CPU, the search (default Budget: 3 KOMO solves, the paper's "
        f"skeleton first) {cs:.1f} s: **x{cs / cp:.2f}** (goal: within x4). Per trial from x{min(ratios.values()):.2f} to "
        f"x{ratios[worst]:.2f} ({worst}). The search's effort was at most the paper's on "
        f"{'every' if never_worse else 'NOT every'} layout. Of the search's time {100 * komo_share:.0f} % is in "
        "lgp.planner.plan_symbolic (closed-form IK seeding and KOMO): KOMO, not the symbolic levels, is what a "
        "wider search pays for.",
        "",
        "| trial | paper CPU s | search CPU s | ratio |",
        "|---|---|---|---|",
        *[f"| {t} | {a:.2f} | {b:.2f} | x{b / a:.2f} |" for t, (a, b) in per_trial.items()],
        "",
        "Profile of one search (cProfile, layout 0 of seed 0; the project's functions by cumulative time, as a share "
        "of the search; cProfile inflates the Python-heavy symbolic levels):",
        "",
        *[f"- {t}: " + "; ".join(rows) for t, rows in profiles.items()],
        "",
        f"**Rearrangements on one core** (BLAS threads 1; REV, SWAP and 20 tasks of `stimuli.generate --kind rearrange "
        f"--seed 0`, {min(r[1] for r in rear)}-{max(r[1] for r in rear)} blocks): the slowest took {max(r[3] for r in rear):.2f} s of CPU and {max(r[4] for r in rear):.2f} s "
        f"wall (goal: under 10 s); median {np.median([r[4] for r in rear]):.2f} s wall; set-asides "
        f"{min(r[2] for r in rear)}-{max(r[2] for r in rear)} per task; {100 * sum(r[5] for r in rear) / sum(r[4] for r in rear):.0f} % of the time in "
        "KOMO.",
        "",
        "| task | blocks | set-asides | CPU s | wall s | effort (J s) | gap (J s) |",
        "|---|---|---|---|---|---|---|",
        *[f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.2f} | {r[4]:.2f} | {r[6]:.4f} | {r[7]:.4f} |" for r in rear],
        "",
        "**Set-aside spots: generated candidates ranked by the bound, not a free pose optimised by KOMO.** The same "
        "skeleton with each set-aside spot drawn at random from the candidates (5 draws; nan: KOMO failed or a carried "
        "block swept through another):",
        "",
        *[f"- {n}: the search's spots {e:.4f} J s; random spots {', '.join(f'{x:.4f}' for x in xs)} J s "
          f"(+{100 * (np.nanmin(xs) / e - 1):.0f} % to +{100 * (np.nanmax(xs) / e - 1):.0f} %); ranking the spots of one "
          f"set-aside takes {1000 * t:.1f} ms" for n, (e, xs, t) in spots.items()],
        "",
        "So where a block is set down moves effort by up to several times, and the bound (which prefers the spot "
        "that shortens both carries) ranks the candidates in milliseconds, while one KOMO solve of these skeletons "
        "costs tenths of a second; a free pose in KOMO would also be a local optimisation from a guess (the spot "
        "the bound ranks first) and need a mode switch with an unknown X_WB, which lgp.komo does not declare.",
    ]
    write_section(args.out, "search", "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark of the geometric planner: reduced vs full KOMO, SNOPT vs IPOPT.

    python bench/komo.py            # writes the "komo" section of docs/benchmarks.md

Towers of n = 1, 5, 10, 15 blocks built from blocks scattered on the table (a fixed
layout per n), planned end to end by lgp.planner.plan (assignment, symbolic plan,
IK seeding, KOMO). Every configuration runs in the same process, one after another,
so the ratios between them are comparable even on a busy machine; absolute seconds
are not. The full program is run up to FULL_MAX blocks (it grows as the slice count
times 7 variables); the cost-on-q variant of it (no auxiliary residuals) only for
one block, to show why the full program is lifted.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import lgp.planner as planner  # noqa: E402
from lgp.paper import BUILD_SITE  # noqa: E402
from models.effort import kinetic_energy  # noqa: E402
from lgp.scene import BLOCK_SIZE, Block, Scene  # noqa: E402

SIZES = (1, 5, 10, 15)
FULL_MAX = 10
REPEATS = 3
SITE = np.array(BUILD_SITE)


def tower_task(n: int, seed: int = 0) -> tuple[Scene, Scene]:
    """n blocks scattered in x [0.2, 0.55], y [-0.3, 0.3] (>= 1 cm apart, >= 4 cm from S) -> tower at S."""
    rng = np.random.default_rng(seed)
    blocks: list[Block] = []
    while len(blocks) < n:
        p = np.array([rng.uniform(0.2, 0.55), rng.uniform(-0.3, 0.3)])
        if np.linalg.norm(p - SITE) < 0.04 + BLOCK_SIZE or any(np.linalg.norm(p - b.p_WB[:2]) < BLOCK_SIZE * 1.5 + 0.01 for b in blocks):
            continue
        blocks.append(Block(f"a{len(blocks) + 1}", [*p, BLOCK_SIZE / 2], yaw=rng.uniform(0, np.pi / 2)))
    tower = [Block(f"b{i + 1}", [*SITE, BLOCK_SIZE * (i + 0.5)]) for i in range(n)]
    return Scene(blocks, label=f"scattered{n}").validate(), Scene(tower, label=f"tower{n}").validate()


def run(A, B, repeats=1, **kw):
    times, p = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        p = planner.plan(A, B, 0, **kw)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), p


def unlifted_full(A, B, options):
    """Solve the 1-block plan's full program with the cost on q: (seconds, cost, status)."""
    from lgp.assignment import assign_blocks
    from lgp.symbolic import symbolic_plan

    arm = planner.default_arm()
    symbolic = symbolic_plan(A, B, assign_blocks(A, B))
    komo, seeds, turns = planner.declare(symbolic, arm, np.random.default_rng(0))
    t0 = time.perf_counter()
    r = komo.solve("full", seeds=seeds, options=options, lifted=False)
    return time.perf_counter() - t0, r.cost, r.status


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    parser.add_argument("--full-max", type=int, default=FULL_MAX)
    args = parser.parse_args(argv)

    load0 = os.getloadavg()[0]
    rows, notes = [], []
    A1, B1 = tower_task(1)
    run(A1, B1)  # warm up: load the arm, import solvers
    for n in SIZES:
        A, B = tower_task(n)
        t_red, red = run(A, B, repeats=REPEATS)
        row = {"n": n, "actions": len(red.actions), "reduced_snopt_s": t_red, "reduced_vars": red.komo.n_variables,
               "effort": kinetic_energy(red), "cost": red.komo.cost}
        t_ip, ip = run(A, B, solver="ipopt")
        row.update(reduced_ipopt_s=t_ip, ipopt_dcost=ip.komo.cost / red.komo.cost - 1)
        if n <= args.full_max:
            t_full, full = run(A, B, formulation="full")
            row.update(full_snopt_s=t_full, full_vars=full.komo.n_variables, full_dcost=full.komo.cost / red.komo.cost - 1,
                       full_deffort=kinetic_energy(full) / kinetic_energy(red) - 1)
        if n == 10:
            fine = [(S, kinetic_energy(run(A, B, slices_per_phase=S)[1])) for S in (40, 80)]
            notes.append("10-block tower, effort (J s) against slices per phase: "
                         + ", ".join(f"{S}: {e:.4f}" for S, e in [(20, kinetic_energy(red)), *fine]))
        rows.append(row)
        print(row, flush=True)
    t_unlifted, c_unlifted, s_unlifted = unlifted_full(A1, B1, {"Hessian full memory": 1})
    _, one = run(A1, B1, formulation="full")
    t_lifted = one.komo.solve_time
    notes.append(f"1-block plan, full program with the cost on q directly (SNOPT, full-memory Hessian): {t_unlifted:.1f} s, "
                 f"{s_unlifted}, cost {c_unlifted:.3f}; lifted (cost on residual variables): {t_lifted:.2f} s, cost {one.komo.cost:.3f} "
                 f"(x{t_unlifted / t_lifted:.0f}).")
    load1 = os.getloadavg()[0]
    section = render(rows, notes, load0, load1, args.full_max)
    write_section(Path(args.out), section)
    print(section)
    return 0


def render(rows, notes, load0, load1, full_max) -> str:
    def f(v, fmt="{:.3f}"):
        return "-" if v is None else fmt.format(v)

    lines = [
        "## komo",
        "",
        "Geometric planner of the effort model (`lgp/komo`, `lgp/planner/`); written by `python bench/komo.py`.",
        "",
        f"`python bench/komo.py`, drake {version('drake')}, {os.cpu_count()} cores shared with other jobs "
        f"(load average {load0:.1f} at the start, {load1:.1f} at the end): seconds are noisy, ratios within a row are "
        "side by side in one process. Tower of n blocks from n scattered blocks (fixed layout per n), 2n actions, "
        "20 slices per phase; time per plan = `lgp.plan` end to end (assignment, symbolic plan, IK seeding, KOMO), "
        f"median of {REPEATS} for reduced/SNOPT, one run otherwise.",
        "",
        "| n | actions | reduced SNOPT s | reduced variables | reduced IPOPT s | IPOPT cost vs SNOPT | full SNOPT s | full variables | full cost vs reduced | full effort vs reduced | effort J s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']} | {r['actions']} | {f(r['reduced_snopt_s'])} | {r['reduced_vars']} | {f(r['reduced_ipopt_s'], '{:.2f}')} | "
            f"{f(r['ipopt_dcost'], '{:+.1e}')} | {f(r.get('full_snopt_s'), '{:.2f}')} | {r.get('full_vars', '-')} | "
            f"{f(r.get('full_dcost'), '{:+.1e}')} | {f(r.get('full_deffort'), '{:+.1e}')} | {r['effort']:.4f} |")
    speed = [r["full_snopt_s"] / r["reduced_snopt_s"] for r in rows if "full_snopt_s" in r]
    lines += [
        "",
        "Variables: joint values plus as many auxiliary residuals (lgp/komo: the cost is |residual|^2). "
        "Time per plan includes re-solves for re-chosen quarter turns when one is predicted to help. "
        f"Full program only up to n = {full_max} (its variables grow with the slice count; 15 blocks is 31 phases x 20 "
        f"slices x 7 joints + residuals). Reduced is {min(speed):.0f}-{max(speed):.0f}x faster than full at equal optimum "
        "(same seeds; the reduced optimum is a KKT point of the full program: every free slice is its exact minimiser).",
        "",
        *[f"- {note}" for note in notes],
    ]
    return "\n".join(lines) + "\n"


def write_section(path: Path, section: str) -> None:
    """Replace the "## komo" section of `path` (up to the next "## " header), or append it; keep the rest."""
    text = path.read_text() if path.exists() else "# Benchmarks\n"
    pattern = re.compile(r"(<!-- komo:begin[^\n]*\n)?## komo\b.*?(?=\n## |\Z)", re.S)
    text = pattern.sub("", text).rstrip("\n") + "\n\n" + section
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


if __name__ == "__main__":
    sys.exit(main())

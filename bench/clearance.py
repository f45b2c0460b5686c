"""Benchmark of the clearance design (approach_height = 0): CPU seconds of a plan
with the reduced program's cost as one quadratic cost over all residuals (as
before) and as one per keyframe (lgp.komo.solve.SPLIT_COST), side by side.

    python bench/clearance.py                          # 3E, layout 0: prints the table
    python bench/clearance.py --trials 3E 7E --out docs/benchmarks.md

Each trial's layout 0 (seed 0) is planned with both forms in one process,
alternating which goes first (repeats > 1), so the ratio is comparable on a busy
machine; absolute seconds are not. CPU seconds (time.process_time: all threads of
this process) and the part spent inside Drake's solvers. The two forms give the
solver the same gradients and the same cost summed in another order; the script
says whether the plans are identical to the bit (joint trajectories, effort; 3E's
are) and exits 1 if they are not.
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.common import machine, write_section  # noqa: E402

SECTION = "clearance design: cost per keyframe"


def plan_cpu(tid: str, split: bool) -> tuple[float, float, float, str]:
    """(CPU s of the plan, CPU s inside the solvers, effort J s, hash of q) of layout 0 of `tid`."""
    import lgp.komo.solve as komo_solve
    import stimuli
    from models.effort import kinetic_energy, plan_of_sample

    solver_cpu = [0.0]
    real = komo_solve._Backend.solve

    def timed(self, prog):
        c0 = time.process_time()
        try:
            return real(self, prog)
        finally:
            solver_cpu[0] += time.process_time() - c0

    komo_solve.SPLIT_COST, komo_solve._Backend.solve = split, timed
    try:
        c0 = time.process_time()
        p = plan_of_sample(stimuli.load_trial(tid), 0, 0, approach_height=0.0)
        cpu = time.process_time() - c0
    finally:
        komo_solve.SPLIT_COST, komo_solve._Backend.solve = True, real
    return cpu, solver_cpu[0], kinetic_energy(p), hashlib.sha256(p.q.tobytes()).hexdigest()[:16]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", nargs="+", default=["3E"])
    parser.add_argument("--repeats", type=int, default=1, help="pairs per trial, alternating which form goes first")
    parser.add_argument("--out", help="write the section to this markdown file (docs/benchmarks.md)")
    args = parser.parse_args(argv)
    before = machine()
    rows, same = [], True
    for tid in args.trials:
        runs = {False: [], True: []}
        for r in range(args.repeats):
            for split in ((False, True) if r % 2 == 0 else (True, False)):
                runs[split].append(plan_cpu(tid, split))
                print(tid, "split" if split else "single", *runs[split][-1], flush=True)
        dense, split = runs[False], runs[True]
        identical = len({x[3] for x in dense + split}) == 1 and len({x[2] for x in dense + split}) == 1
        same &= identical
        d, s = sum(x[0] for x in dense), sum(x[0] for x in split)
        ds, ss = sum(x[1] for x in dense), sum(x[1] for x in split)
        rows.append(f"| {tid} | {d / len(dense):.1f} ({ds / len(dense):.1f}) | {s / len(split):.1f} ({ss / len(split):.1f}) "
                    f"| {d / s:.2f} | {dense[0][2]:.6f} | {'yes' if identical else 'NO'} |")
    text = "\n".join([
        f"## {SECTION}", "",
        "    python bench/clearance.py" + (" --trials " + " ".join(args.trials) if args.trials != ["3E"] else "")
        + (f" --repeats {args.repeats}" if args.repeats != 1 else ""), "",
        "Layout 0 (seed 0) planned with the clearance design (approach_height = 0), the reduced program's cost "
        "|z|^2 written as one quadratic cost over all residuals (before) or one per keyframe "
        "(`lgp.komo.solve.SPLIT_COST`), side by side in one process. CPU s per plan (in brackets: inside the "
        f"solvers); {args.repeats} pair(s) per trial, alternating which goes first.", "",
        f"Machine at the start: {before}; at the end: {machine()}.", "",
        "| trial | one cost: CPU s | per keyframe: CPU s | ratio | effort J s | plans identical |",
        "|---|---|---|---|---|---|", *rows, ""])
    print(text)
    if args.out:
        write_section(Path(args.out), SECTION, text)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())

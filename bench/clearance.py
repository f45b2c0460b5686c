"""Benchmark of the clearance design (approach_height = 0): CPU seconds of a plan
with the reduced program's cost as one quadratic cost over all residuals (as
before) and as one per keyframe (lgp.komo.solve.SPLIT_COST), side by side; with
--options, IPOPT's defaults against lgp.planner.clearance.CLEARANCE_OPTIONS.

    python bench/clearance.py                          # 3E, layout 0: prints the table
    python bench/clearance.py --trials 3E 7E --out docs/benchmarks.md
    python bench/clearance.py --options --trials all   # IPOPT options, every trial of the paper

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
OPTIONS_SECTION = "clearance design: IPOPT options"
#: --options: the two plans count as the same optimum if every effort agrees within
#: this (relative; IPOPT's tol is 1e-9 before, CLEARANCE_OPTIONS' 1e-6 after) and every
#: joint within OPTIONS_Q_TOLERANCE rad.
OPTIONS_EFFORT_TOLERANCE = 1e-6
OPTIONS_Q_TOLERANCE = 1e-4


def plan_options(tid: str, tuned: bool):
    """(CPU s of the plan, CPU s inside the solvers, effort J s, q) of layout 0 of `tid`,
    with CLEARANCE_OPTIONS (tuned) or IPOPT's defaults (none)."""
    import lgp.planner.clearance as clearance

    kept = clearance.CLEARANCE_OPTIONS
    clearance.CLEARANCE_OPTIONS = kept if tuned else {}
    try:
        return plan_cpu(tid, True, keep_q=True)
    finally:
        clearance.CLEARANCE_OPTIONS = kept


def plan_cpu(tid: str, split: bool, keep_q: bool = False) -> tuple[float, float, float, str]:
    """(CPU s of the plan, CPU s inside the solvers, effort J s, hash of q (q itself if
    keep_q)) of layout 0 of `tid`."""
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
    return cpu, solver_cpu[0], kinetic_energy(p), p.q.copy() if keep_q else hashlib.sha256(p.q.tobytes()).hexdigest()[:16]


def main_options(args) -> int:
    """--options: IPOPT's defaults (before) and CLEARANCE_OPTIONS (after), side by side."""
    import numpy as np

    from lgp.paper import TRIAL_IDS
    from lgp.planner.clearance import CLEARANCE_OPTIONS

    trials = list(TRIAL_IDS) if args.trials == ["all"] else args.trials
    before = machine()
    rows, same, totals = [], True, [0.0, 0.0]
    for tid in trials:
        runs = {False: [], True: []}
        for r in range(args.repeats):
            for tuned in ((False, True) if r % 2 == 0 else (True, False)):
                runs[tuned].append(plan_options(tid, tuned))
                print(tid, "tuned" if tuned else "defaults", *runs[tuned][-1][:3], flush=True)
        d, t = (sum(x[0] for x in runs[k]) / len(runs[k]) for k in (False, True))
        ds, ts = (sum(x[1] for x in runs[k]) / len(runs[k]) for k in (False, True))
        e0, e1 = runs[False][0][2], runs[True][0][2]
        de = max(abs(x[2] - e0) / e0 for x in runs[False] + runs[True])
        dq = max(float(np.max(np.abs(x[3] - runs[False][0][3]))) for x in runs[False] + runs[True])
        ok = de <= OPTIONS_EFFORT_TOLERANCE and dq <= OPTIONS_Q_TOLERANCE
        same &= ok
        totals[0] += d
        totals[1] += t
        rows.append(f"| {tid} | {d:.1f} ({ds:.1f}) | {t:.1f} ({ts:.1f}) | {d / t:.2f} | {e0:.6f} | {de:.1e} | {dq:.1e} "
                    f"| {'yes' if ok else 'NO'} |")
    rows.append(f"| all | {totals[0]:.1f} | {totals[1]:.1f} | {totals[0] / totals[1]:.2f} | | | | |")
    text = "\n".join([
        f"## {OPTIONS_SECTION}", "",
        "    python bench/clearance.py --options" + (" --trials " + " ".join(args.trials) if args.trials != ["3E"] else "")
        + (f" --repeats {args.repeats}" if args.repeats != 1 else ""), "",
        "Layout 0 (seed 0) planned with the clearance design (approach_height = 0), its IPOPT solves with "
        f"lgp.komo.solve's defaults (before) or also `lgp.planner.clearance.CLEARANCE_OPTIONS` = {CLEARANCE_OPTIONS} "
        "(after), side by side in one process. CPU s per plan (in brackets: inside the solvers); "
        f"{args.repeats} pair(s) per trial, alternating which goes first. Same optimum: efforts within "
        f"{OPTIONS_EFFORT_TOLERANCE:g} relative and joints within {OPTIONS_Q_TOLERANCE:g} rad.", "",
        f"Machine at the start: {before}; at the end: {machine()}.", "",
        "| trial | defaults: CPU s | tuned: CPU s | ratio | effort J s | effort rel. diff | max joint diff rad | same optimum |",
        "|---|---|---|---|---|---|---|---|", *rows, ""])
    print(text)
    if args.out:
        write_section(Path(args.out), OPTIONS_SECTION, text)
    return 0 if same else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", nargs="+", default=["3E"])
    parser.add_argument("--repeats", type=int, default=1, help="pairs per trial, alternating which form goes first")
    parser.add_argument("--out", help="write the section to this markdown file (docs/benchmarks.md)")
    parser.add_argument("--options", action="store_true",
                        help="compare IPOPT's defaults with lgp.planner.clearance.CLEARANCE_OPTIONS (--trials all: every trial)")
    args = parser.parse_args(argv)
    if args.options:
        return main_options(args)
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

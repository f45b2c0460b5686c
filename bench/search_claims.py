"""What the search's claims rest on, measured with KOMO (docs/effort.md, "The search").

    python bench/search_claims.py       # ~1 min on one core; writes the "search: orders and relays" section

1. **Orders.** 2H, layout 0 (seed 0): B is four blocks on the table, so every order of
   the search's four carries is legal. Each of the 24 orders is solved by KOMO: the
   bound (a sum over carries) is the same for all, the effort is not, so a closed gap
   ("no other set of carries can beat the plan") is not least effort over orders.
2. **Relays.** The effort measure's own incentive: with fixed 1 s phases a carry split
   at its midpoint (a set-aside on the table, then on to the slot) buys a second of
   time and lowers the time integral of kinetic energy. Each carry of the paper plan of
   10H and 7H, layout 0, is split at the midpoint of its start and end on the table and
   solved by KOMO, against the plan as it is.
"""
from __future__ import annotations

import itertools
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from common import machine, write_section  # noqa: E402

import stimuli  # noqa: E402
from lgp.planner import PlanningError, plan, plan_symbolic  # noqa: E402
from lgp.scene import TABLE  # noqa: E402
from lgp.search import kinetic_energy, search, skeleton_bound  # noqa: E402
from lgp.symbolic import Grasp, IllegalActionError, PlanState, Place, SymbolicPlan, apply  # noqa: E402
from models.effort import sample_rng  # noqa: E402


def _legal(symbolic: SymbolicPlan) -> bool:
    state = PlanState(symbolic.initial)
    try:
        for action in symbolic.actions:
            state = apply(action, state)
    except IllegalActionError:
        return False
    return True


def orders(trial_id: str = "2H") -> list[str]:
    trial = stimuli.load_trial(trial_id)
    rng = sample_rng(0, 0)
    result = search(trial.sample_initial(rng), trial.target, rng)
    s = result.symbolic
    carries = [s.actions[k:k + 2] for k in range(0, len(s.actions), 2)]
    rows = []
    for perm in itertools.permutations(range(len(carries))):
        other = SymbolicPlan(s.initial, s.target, s.assignment, tuple(a for k in perm for a in carries[k]))
        if not _legal(other):
            continue
        effort = kinetic_energy(plan_symbolic(other, np.random.default_rng(0)))
        rows.append((perm, skeleton_bound(other), effort))
    efforts = [e for _, _, e in rows]
    bounds = [b for _, b, _ in rows]
    own = next(e for p, _, e in rows if p == tuple(range(len(carries))))
    rev = next(e for p, _, e in rows if p == tuple(reversed(range(len(carries)))))
    return [f"### orders: {trial_id}, layout 0, the search's {len(carries)} carries in every legal order "
            f"({len(rows)} of {len(list(itertools.permutations(carries)))})", "",
            f"- search's plan ({result.stopped}, gap {result.gap:.4f} J s): {result.effort:.6f} J s "
            f"(the same order re-solved: {own:.6f})",
            f"- reversed order: {rev:.6f} J s ({100 * (rev / own - 1):+.2f} %)",
            f"- all orders: {min(efforts):.6f} - {max(efforts):.6f} J s "
            f"({100 * (min(efforts) / own - 1):+.2f} % to {100 * (max(efforts) / own - 1):+.2f} %)",
            f"- bound of every order: {min(bounds):.6f} - {max(bounds):.6f} J s", ""]


def relays(trial_ids=("10H", "7H")) -> list[str]:
    lines = ["### relays: each carry of the paper plan (layout 0) split at its midpoint on the table", "",
             "| trial | carry | block | distance (m) | plan (J s) | relayed (J s) | change | bound before -> after (J s) |",
             "|---|---|---|---|---|---|---|---|"]
    for tid in trial_ids:
        trial = stimuli.load_trial(tid)
        rng = sample_rng(0, 0)
        p0 = plan(trial.sample_initial(rng), trial.target, rng)
        s = p0.symbolic
        base = kinetic_energy(p0)
        where = {b.name: np.asarray(b.p_WB, float) for b in s.initial.blocks}
        for k in range(0, len(s.actions), 2):
            grasp, place = s.actions[k], s.actions[k + 1]
            a, b = where[place.block], np.asarray(place.p_WB, float)
            where[place.block] = b
            mid = np.array([(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, s.initial.block(place.block).size[2] / 2])
            acts = s.actions[:k] + (grasp, Place(place.block, (TABLE,), mid, 0.0), Grasp(place.block), place) + s.actions[k + 2:]
            relayed = SymbolicPlan(s.initial, s.target, s.assignment, acts)
            row = f"| {tid} | {k // 2 + 1} | {place.block} | {np.linalg.norm(b - a):.3f} | {base:.4f} | "
            if not _legal(relayed):
                lines.append(row + "midpoint not free | | |")
                continue
            try:
                e = kinetic_energy(plan_symbolic(relayed, np.random.default_rng(0)))
            except PlanningError as err:
                lines.append(row + f"no plan ({str(err)[:40]}) | | |")
                continue
            lines.append(row + f"{e:.4f} | {100 * (e / base - 1):+.1f} % | {skeleton_bound(s):.4f} -> {skeleton_bound(relayed):.4f} |")
    return lines + [""]


def main() -> int:
    t0, c0 = time.perf_counter(), time.process_time()
    start = machine()
    lines = ["## search: orders and relays", "",
             "Written by `python bench/search_claims.py` (KOMO, SNOPT, the legs design, 20 slices a phase).", "",
             *orders(), *relays(),
             f"- machine before: {start}", f"- after: {machine()}",
             f"- took {time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} CPU-s"]
    print("\n".join(lines))
    write_section(ROOT / "docs" / "benchmarks.md", "search: orders and relays", "\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

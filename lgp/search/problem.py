"""The fixed data of one search (`Problem`): blocks of A, slots of B and their
supports, the set-aside spots created so far, where each block stands in a
symbolic state, the pose level (closed-form IK of a carry's keyframes, memoised)
and the bound on the effort still to come (`remaining_bound`)."""
from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from lgp.planner import SEED_MARGIN, SWIVELS
from lgp.scene import CONTACT_TOLERANCE, MIN_SUPPORT_AREA, TABLE, Scene, footprint_overlap_area, support_graph
from lgp.search.bound import carry_bound
from lgp.symbolic import enters_any, nearby_solids, same_pose


class Problem:
    """The fixed data of one search: blocks of A, slots of B and their supports,
    the spots created so far, and memoised geometry."""

    def __init__(self, initial: Scene, target: Scene, approach_height: float, slices_per_phase: int, arm):
        self.initial, self.target = initial, target
        self.h, self.S, self.arm = approach_height, slices_per_phase, arm
        self.blocks = list(initial.blocks)
        self.slots = list(target.blocks)
        self.colour = [b.colour for b in self.blocks]
        self.slot_colour = [s.colour for s in self.slots]
        graph_B = support_graph(target)
        index_B = {s.name: j for j, s in enumerate(self.slots)}
        self.fixed_names = {f.name for f in initial.fixed} | {TABLE}
        # per slot: the slots it rests on in B, and the fixed solids / table it rests on
        self.slot_below = [[index_B[n] for n in graph_B[s.name] if n in index_B] for s in self.slots]
        self.slot_ground = [[n for n in graph_B[s.name] if n not in index_B] for s in self.slots]
        self.spots: list[tuple[np.ndarray, float]] = []  # (p_WB, yaw)
        self._spot_index: dict[tuple, int] = {}
        self._reach: dict[tuple, bool] = {}
        self.slot_p = np.array([s.p_WB for s in self.slots]).reshape(-1, 3)
        # A block of A with a fixed box resting on it can never be grasped.
        self.pinned = [any(abs(f.bottom - b.top) <= CONTACT_TOLERANCE and footprint_overlap_area(b, f) > MIN_SUPPORT_AREA
                           for f in initial.fixed) for b in self.blocks]
        self.start_p = initial.positions

    # -- positions and scenes
    def pose(self, i: int, w: int) -> tuple[np.ndarray, float]:
        if w == 0:
            return self.blocks[i].p_WB, self.blocks[i].yaw
        if w > 0:
            return self.slots[w - 1].p_WB, self.slots[w - 1].yaw
        return self.spots[-1 - w]

    def scene(self, where) -> Scene:
        return self.initial.with_blocks(b if w == 0 else b.moved_to(*self.pose(i, w)) for i, (b, w) in enumerate(zip(self.blocks, where)))

    def spot(self, p_WB, yaw: float) -> int:
        key = (round(float(p_WB[0]), 6), round(float(p_WB[1]), 6), round(float(yaw), 6))
        if key not in self._spot_index:
            self._spot_index[key] = len(self.spots)
            self.spots.append((np.asarray(p_WB, float), float(yaw)))
        return -1 - self._spot_index[key]

    def bound(self, p_from, p_to):
        return carry_bound(p_from, p_to, approach_height=self.h, slices_per_phase=self.S)

    # -- the pose level: closed-form IK of a carry's keyframes
    def reachable(self, p_WB, yaw: float) -> bool:
        """Whether the arm reaches the pose from above and the point approach_height
        above it at the same quarter turn, branch and swivel (as the planner seeds)."""
        key = (round(float(p_WB[0]), 6), round(float(p_WB[1]), 6), round(float(p_WB[2]), 6), round(float(yaw), 6))
        if key not in self._reach:
            swivels = np.linspace(-np.pi, np.pi, SWIVELS, endpoint=False)
            up = np.array([0.0, 0.0, self.h])
            poses = [(np.asarray(p_WB, float), float(yaw))] + ([(np.asarray(p_WB, float) + up, float(yaw))] if self.h > 0 else [])
            _, ok = self.arm.ik_grids_from_above(poses, swivels, margin=SEED_MARGIN)
            self._reach[key] = bool(np.all(ok, axis=0).any())
        return self._reach[key]

    # -- which blocks are final, clear, in the way
    def final_from_start(self) -> tuple[int, ...]:
        """Blocks of A already at a slot pose of their colour, on supports that are
        themselves final (or fixed): where (1 + j) for those, 0 for the rest."""
        where = [0] * len(self.blocks)
        graph_A = support_graph(self.initial)
        index_A = {b.name: i for i, b in enumerate(self.blocks)}
        taken = set()

        def final(i, seen=()):
            if where[i] > 0:
                return True
            if i in seen:
                return False
            b = self.blocks[i]
            for j, s in enumerate(self.slots):
                if j in taken or s.colour != b.colour or not same_pose(b.p_WB, b.yaw, s.p_WB, s.yaw, b.size):
                    continue
                if all(n in self.fixed_names or final(index_A[n], seen + (i,)) for n in graph_A[b.name]):
                    where[i] = 1 + j
                    taken.add(j)
                    return True
            return False

        for i in range(len(self.blocks)):
            final(i)
        return tuple(where)

    def settled(self, where, scene: Scene, above: dict) -> bool:
        """Whether no state reachable from this one is stuck: no block outside the
        slots has a block on it or stands in an unfilled slot's volume. Then every
        ready slot's volume stays free and its colour has a clear block (the
        colour count is checked by the bound), and nothing ever covers such a
        block again: a placed block rests only on slots. So set-asides never
        happen below, and direct carries bound the rest."""
        movers = [i for i, w in enumerate(where) if w <= 0]
        if any(above[self.blocks[i].name] for i in movers):
            return False
        unfilled = [s for j, s in enumerate(self.slots) if (1 + j) not in where]
        if not unfilled:
            return True
        return not any(enters_any(scene.blocks[i], nearby_solids(scene.blocks[i], unfilled)) for i in movers)

    def remaining_bound(self, where, settled: bool = False) -> tuple[float, float]:
        """Two estimates of the effort still to come, by minimum-cost assignment of
        a distinct block of its colour, not in a slot, to every unfilled slot:

        - a lower bound: each carried from where it is now, directly or (a block
          still at its start, which may yet be set aside) via one set-aside, the
          better of one carry and two through the midpoint;
        - the guide: direct carries only (what the best-first order follows; it is
          the bound whenever no set-aside is to come, as on every paper trial).

        The two agree when the state is `settled`. (inf, inf) when the colours
        cannot fill the slots."""
        free = [j for j in range(len(self.slots)) if (1 + j) not in where]
        if not free:
            return 0.0, 0.0
        movers = [i for i, w in enumerate(where) if w <= 0]
        if len(movers) < len(free):
            return np.inf, np.inf
        ok = np.array([[self.colour[i] == self.slot_colour[j] for j in free] for i in movers])
        if not ok.any(axis=0).all():
            return np.inf, np.inf
        p_from = np.array([self.pose(i, where[i])[0] for i in movers])
        p_to = self.slot_p[free]
        direct = self.bound(p_from[:, None], p_to[None])
        relay = 2 * self.bound(p_from[:, None], (p_from[:, None] + p_to[None]) / 2)
        at_start = np.array([where[i] == 0 for i in movers])
        out = []
        lower = direct if settled else np.where(at_start[:, None], np.minimum(direct, relay), direct)
        for cost in (lower, direct):
            big = 1e6 + cost.max()
            rows, cols = linear_sum_assignment(np.where(ok, cost, big))
            if not ok[rows, cols].all() or len(cols) < len(free):
                return np.inf, np.inf
            out.append(float(cost[rows, cols].sum()))
        return out[0], out[1]

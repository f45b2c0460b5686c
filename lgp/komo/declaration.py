"""Declaring a KOMO problem on a phase clock, rai-style (no solving here).

    komo = Komo(arm, phases=3, slices_per_phase=20, k_order=2, objects={"b1": X_WB})
    komo.add_objective([0.8], "pose", ("G",), "eq", target=X_WG_pregrasp)
    komo.add_mode_switch(1.0, "grasp", "G", "b1", X_GB=X_GB)
    komo.add_rest(1.0)

Time. Phase p runs over slices; slice s = 0 .. N-1 (N = phases * slices_per_phase)
sits at time (s + 1) * tau, tau = phase_duration / slices_per_phase; a phase time p
maps to slice round(p * slices_per_phase) - 1. Before slice 0 come k_order prefix
slices fixed at `q_home`: the motion starts at rest at home (rai's prefix).

Kinematic modes. Objects (blocks) are not bodies of the plant: an object is either
free, at a constant pose, or held by a gripper frame G with a fixed X_GB between a
"grasp" and a "place" mode switch, so that X_WB(q) = X_WG(q) X_GB. A grasp switch
also constrains the gripper to the grasp pose X_WG = X_WB X_GB^-1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

#: Features a declared objective may use.
FEATURES = ("qItself", "position", "pose")
#: Objective types, as in rai: equality, inequality (feature - target <= 0), sum of squares.
TYPES = ("eq", "ineq", "sos")


class KomoError(ValueError):
    """A declaration that cannot be turned into a program (bad time, frame, feature)."""


@dataclass(frozen=True)
class Objective:
    """One declared objective: `feature` of `frames` at the decision slices `slices`."""

    slices: tuple[int, ...]
    feature: str
    frames: tuple[str, ...]
    type: str
    scale: float | tuple[float, float, float]
    target: object
    order: int
    time: tuple[float, ...]
    lazy: bool = False
    points: tuple[tuple[float, float, float], ...] | None = None  # "position": points Q fixed on the frame (p_FQ), not its origin
    X_WA: RigidTransform | None = None  # "position": measured and expressed in this fixed frame A, not the world


@dataclass(frozen=True)
class ModeSwitch:
    slice: int
    time: float
    mode: str
    gripper: str
    object: str
    X_GB: RigidTransform | None


class Declaration:
    """A KOMO problem declared on a phase clock over a Drake MultibodyPlant.

    `arm` is an `lgp.arm.Arm` or anything with `plant` (finalized MultibodyPlant),
    `q_home`, `q_lower`, `q_upper`; or a bare MultibodyPlant (then `q_home` must be
    given). `objects` maps object names to their initial world pose X_WB.
    (`lgp.komo.Komo` is this plus solving and evaluation.)
    """

    def __init__(self, arm, phases: int, slices_per_phase: int, k_order: int = 2, *, phase_duration: float = 1.0,
                 q_home=None, objects: dict[str, RigidTransform] | None = None):
        plant = getattr(arm, "plant", arm)
        self.plant = plant
        self.context = plant.CreateDefaultContext()
        self.nq = plant.num_positions()
        home = q_home if q_home is not None else getattr(arm, "q_home", None)
        if home is None:
            raise KomoError("Komo needs q_home (the rest configuration at time 0)")
        self.q_home = np.asarray(home, float).reshape(self.nq)
        self.q_lower = np.asarray(getattr(arm, "q_lower", plant.GetPositionLowerLimits()), float)
        self.q_upper = np.asarray(getattr(arm, "q_upper", plant.GetPositionUpperLimits()), float)
        if phases < 1 or slices_per_phase < 1 or k_order < 1:
            raise KomoError(f"Komo needs phases, slices_per_phase, k_order >= 1, got {phases}, {slices_per_phase}, {k_order}")
        self.phases, self.slices_per_phase, self.k_order = int(phases), int(slices_per_phase), int(k_order)
        self.phase_duration = float(phase_duration)
        self.tau = self.phase_duration / self.slices_per_phase
        self.N = self.phases * self.slices_per_phase
        self.objects = {name: RigidTransform(X) for name, X in (objects or {}).items()}
        self.objectives: list[Objective] = []
        self.switches: list[ModeSwitch] = []
        self.rests: list[tuple[int, bool]] = []  # (slice, also after it)

    def slice_of(self, time: float) -> int:
        s = int(round(time * self.slices_per_phase)) - 1
        if not 0 <= s < self.N or abs((s + 1) - time * self.slices_per_phase) > 1e-9:
            raise KomoError(f"time {time} (phases) is not a slice of 0 < t <= {self.phases} at {self.slices_per_phase} slices per phase")
        return s

    def _slices(self, times) -> tuple[int, ...]:
        if times is None or len(times) == 0:
            return tuple(range(self.N))
        if len(times) == 1:
            return (self.slice_of(times[0]),)
        if len(times) == 2:
            return tuple(range(self.slice_of(times[0]), self.slice_of(times[1]) + 1))
        raise KomoError(f"times must be [], [t] or [t_start, t_end], got {times}")

    def add_objective(self, times, feature: str, frames=(), type: str = "sos", scale=1.0, target=None, order: int = 0,
                      lazy: bool = False, points=None, X_WA: RigidTransform | None = None):
        """Declare `feature` of `frames` at `times` ([t], [t0, t1] or [] for all).

        Features: "qItself" (the joint vector, or its order-th time derivative;
        linear), "position" (p_WF of a plant frame or object, target a 3-vector;
        a 3-vector `scale` with zeros leaves those axes free),
        "pose" (X_WF, target a RigidTransform). Types: "eq", "ineq" (feature - target
        <= 0, componentwise; position only; a negative scale flips an axis to >=, as
        in rai) and "sos" (scale^2 |feature - target|^2 added to the cost; qItself
        only, so the cost stays quadratic). A `lazy` constraint is only imposed by the
        reduced formulation once the solution violates it (its slice is then promoted
        to a keyframe and the program re-solved), which keeps it exact but cheap when
        it is mostly inactive; the full formulation imposes it everywhere from the start.
        "position" may instead constrain `points` (m, 3) fixed on the frame (p_FQ,
        e.g. a held block's corners; one constraint each, the same bounds), and be
        measured and expressed in a fixed frame `X_WA` (e.g. an obstacle's) instead of
        the world: p_AQ = X_WA^-1 p_WQ.
        Time derivatives are backward differences, as in rai.
        """
        if feature not in FEATURES:
            raise KomoError(f"unknown feature {feature!r} (known: {', '.join(FEATURES)})")
        if type not in TYPES:
            raise KomoError(f"unknown objective type {type!r} (known: {', '.join(TYPES)})")
        frames = (frames,) if isinstance(frames, str) else tuple(frames)
        if feature != "qItself":
            if order != 0:
                raise KomoError(f"feature {feature} supports order 0 only")
            if type == "sos":
                raise KomoError(f"sos objectives on {feature} are not supported (the reduced formulation needs a quadratic cost)")
            if type == "ineq" and feature == "pose":
                raise KomoError("ineq objectives on pose are not supported")
            if len(frames) != 1:
                raise KomoError(f"feature {feature} takes one frame, got {frames}")
            if frames[0] not in self.objects:
                self.frame(frames[0])  # raises if unknown
        elif order > self.k_order and type != "sos":
            raise KomoError(f"qItself of order {order} needs k_order >= {order}")
        if feature == "position":
            target = np.asarray(target, float).reshape(3)
        elif feature == "pose":
            target = RigidTransform(target)
        elif target is not None:
            target = np.broadcast_to(np.asarray(target, float), (self.nq,)).copy()
        times = tuple(float(t) for t in (times or ()))
        scale = float(scale) if np.ndim(scale) == 0 else tuple(float(v) for v in np.reshape(scale, 3))
        if lazy and (feature == "qItself" or type == "sos"):
            raise KomoError("only nonlinear eq/ineq objectives can be lazy")
        if (points is not None or X_WA is not None) and feature != "position":
            raise KomoError(f"points and X_WA apply to position objectives, not {feature}")
        if points is not None:
            points = np.asarray(points, float)
            if points.ndim != 2 or points.shape[1] != 3 or not len(points) or not np.all(np.isfinite(points)):
                raise KomoError(f"points must be an (m, 3) array of finite positions, got shape {points.shape}")
            points = tuple(tuple(float(v) for v in row) for row in points)
        X_WA = None if X_WA is None else RigidTransform(X_WA)
        self.objectives.append(Objective(self._slices(times), feature, frames, type, scale, target, int(order), times, bool(lazy),
                                         points, X_WA))
        return self

    def add_mode_switch(self, time: float, mode: str, gripper: str, obj: str, X_GB: RigidTransform | None = None, X_WB=None):
        """Declare a kinematic mode switch of object `obj` at phase `time`.

        "grasp": from this slice on `obj` moves with `gripper` as X_WB = X_WG X_GB;
        the gripper is constrained to X_WG = X_WB X_GB^-1 at this slice (X_GB
        required). "place": after this slice `obj` stays where it is; with X_WB
        given, also declares the eq objective "pose of obj = X_WB" at this slice.
        """
        if mode not in ("grasp", "place"):
            raise KomoError(f"unknown mode {mode!r} (known: grasp, place)")
        if obj not in self.objects:
            raise KomoError(f"mode switch on unknown object {obj!r} (declare it in objects=)")
        self.frame(gripper)
        if mode == "grasp" and X_GB is None:
            raise KomoError(f"grasp of {obj} at phase {time} needs X_GB (the object's pose in the gripper)")
        s = self.slice_of(time)
        self.switches.append(ModeSwitch(s, float(time), mode, gripper, obj, None if X_GB is None else RigidTransform(X_GB)))
        self.switches.sort(key=lambda m: (m.slice, m.mode != "place"))
        if mode == "place" and X_WB is not None:
            self.add_objective([time], "pose", (obj,), "eq", target=X_WB)
        return self

    def add_rest(self, time: float, after: bool = True):
        """Zero velocity at phase `time`, to second order, without standing still a slice.

        Imposes (3 q[s] - 4 q[s-1] + q[s-2]) / (2 tau) = 0 and, with `after`, the same
        one-sided difference forward: the motion comes to rest at s and leaves it
        tangentially. (rai's order-1 feature, (q[s] - q[s-1]) / tau = 0, makes the
        arm stand still for a whole slice, which shortens the neighbouring moves by
        tau each and biased a 20-slice-per-phase plan's effort by 4 %.)
        """
        s = self.slice_of(time)
        if s < 1 or (after and s > self.N - 3):
            raise KomoError(f"a rest at phase {time} needs two slices on each side it constrains")
        self.rests.append((s, bool(after)))
        return self

    # ------------------------------------------------------------------ reading the declaration

    def frame(self, name: str):
        """The plant frame `name`; KomoError if the plant has none."""
        if not self.plant.HasFrameNamed(name):
            raise KomoError(f"no frame or object named {name!r} in the plant or objects")
        return self.plant.GetFrameByName(name)

    def holder(self, obj: str, s: int):
        """(gripper frame name, X_GB) if `obj` is held at slice s, else None."""
        held = None
        for m in self.switches:
            if m.object != obj or m.slice > s:
                continue
            if m.mode == "grasp":
                held = (m.gripper, m.X_GB)
            elif m.slice < s:
                held = None
        return held

    def grasp_objectives(self) -> list[Objective]:
        """The gripper-at-grasp-pose objective implied by each grasp switch."""
        out = []
        for m in self.switches:
            if m.mode == "grasp":
                X_WB = self.free_pose(m.object, m.slice)
                out.append(Objective((m.slice,), "pose", (m.gripper,), "eq", 1.0, X_WB.multiply(m.X_GB.inverse()), 0, (m.time,)))
        return out

    def free_pose(self, obj: str, s: int) -> RigidTransform:
        """Pose of `obj` when grasped at slice s: initial, or the target of its last place."""
        X = self.objects[obj]
        for m in self.switches:
            if m.object == obj and m.mode == "place" and m.slice < s:
                X = next((o.target for o in self.objectives if o.feature == "pose" and o.frames == (obj,) and m.slice in o.slices), None)
                if X is None:
                    raise KomoError(f"{obj} is grasped at slice {s} after a place without a declared pose target")
        return X

    def nonlinear(self) -> list[tuple[Objective, int]]:
        """Every (objective, slice) with a nonlinear feature, grasp poses included."""
        return [(o, s) for o in (*self.objectives, *self.grasp_objectives()) if o.feature != "qItself" for s in o.slices]

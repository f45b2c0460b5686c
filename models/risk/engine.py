"""What every physics engine of the risk model shares: the block material, the
4-s rollout with early termination, and the engine registry.

An engine keeps one compiled model per layout (block count, block sizes and fixed
boxes) and reuses it for every run: a run resets the state, places the blocks and
steps. Engines are looked up by name with `get_engine`; a process keeps one
instance of each, so a worker of a process pool compiles each layout once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lgp.errors import InputError
from lgp.geometry import digest
from lgp.paper import BLOCK_SIZE, DURATION
from lgp.scene import Scene

#: Wood (kg/m^3) and wood-on-wood friction, for blocks, table and fixed boxes.
DENSITY = 600.0
FRICTION = 0.6
#: Early termination is checked every CHECK_INTERVAL s of simulated time: the run
#: stops as a fall once a block has moved `stop_distance` * d horizontally (the
#: risk model's: FALL_CERTAIN, or twice the fall threshold if that is larger,
#: models.risk.model.fall_certain), and as a stand
#: once every point of every block has moved slower than REST_SPEED for
#: REST_WINDOW s in a row without speeding up by more than REST_SLACK over that
#: window (a structure that starts to topple from rest speeds up slowly at first),
#: or once the engine has put every block to sleep.
FALL_CERTAIN = 1.0
CHECK_INTERVAL = 0.025
REST_SPEED = 0.005
REST_WINDOW = 0.3
REST_SLACK = 0.0002


class RestWatch:
    """The rest rule of a run (module comment above): fed the fastest point speed of
    the moving blocks at each check, `update(t, fastest)` says when the run is at
    rest: every point slower than REST_SPEED for REST_WINDOW s in a row, without
    speeding up by more than REST_SLACK over that window (a speed-up starts the
    window again). `reset(t)` starts over, e.g. after a block was taken out."""

    __slots__ = ("since", "speed")

    def __init__(self):
        self.since, self.speed = 0.0, np.inf

    def reset(self, t: float) -> None:
        self.since, self.speed = t, np.inf

    def update(self, t: float, fastest: float) -> bool:
        if fastest >= REST_SPEED:
            self.since, self.speed = t, np.inf
        elif self.speed == np.inf:
            self.since, self.speed = t, fastest
        elif t - self.since >= REST_WINDOW - 1e-9:
            if fastest <= self.speed + REST_SLACK:
                return True
            self.since, self.speed = t, fastest  # speeding up: watch again
        return False


@dataclass(frozen=True)
class Rollout:
    """One simulated run: block centres at the start and at the end (n, 3), the
    simulated time (s) and whether it ended early."""

    p_WB_start: np.ndarray
    p_WB_final: np.ndarray
    sim_time: float
    stopped_early: bool

    def horizontal_displacement(self) -> np.ndarray:
        """Per-block distance (m) between final and start centre in the xy-plane."""
        return np.linalg.norm(self.p_WB_final[:, :2] - self.p_WB_start[:, :2], axis=1)

    def displacement_3d(self) -> np.ndarray:
        return np.linalg.norm(self.p_WB_final - self.p_WB_start, axis=1)


class Engine:
    """Base class: subclasses build a model for a layout and step it.

    Subclass contract: `_load(scene, p_WB)` (make the model for the scene's layout
    current and place its blocks at rest, centres at p_WB (n, 3), orientations as in
    the scene), `_advance(t)` (step to simulated time t),
    `_state()` -> (p_WB (n, 3), fastest point speed per block (n,)), and
    `_asleep()` -> True when the engine has put every block to sleep.
    """

    name = "?"

    def settings(self) -> dict:
        """Engine settings worth recording next to results."""
        return {}

    def simulate(self, scene: Scene, duration: float = DURATION, early_stop: bool = True,
                 stop_distance: float = FALL_CERTAIN, p_WB: np.ndarray | None = None) -> Rollout:
        """Run `scene` from rest for `duration` s (less with early termination;
        `stop_distance`, in units of d, is how far a block must have moved
        horizontally for the run to stop as a certain fall). `p_WB` (n, 3): start the blocks at these
        centres instead of the scene's (a noisy copy of the same layout, orientations
        unchanged), the same as simulating the moved scene without building it."""
        self._load(scene, scene.positions if p_WB is None else np.asarray(p_WB, float).reshape(len(scene), 3))
        p_start, _ = self._state()
        if not len(scene):
            return Rollout(p_start, p_start, 0.0, False)
        certain = stop_distance * smallest_width(scene)
        xy_start = p_start[:, :2]
        t, watch = 0.0, RestWatch()
        n_checks = int(round(duration / CHECK_INTERVAL))
        for k in range(1, n_checks + 1):
            t = min(duration, k * CHECK_INTERVAL)
            self._advance(t)
            if not early_stop:
                continue
            p, speed = self._state()
            if row_norms(p[:, :2] - xy_start).max() > certain:
                return Rollout(p_start, p, t, t < duration)
            if self._asleep():
                return Rollout(p_start, p, t, t < duration)
            if watch.update(t, float(speed.max()) if len(speed) else 0.0):
                return Rollout(p_start, p, t, t < duration)
        p, _ = self._state()
        return Rollout(p_start, p, t, False)

    # subclass hooks
    def _load(self, scene: Scene, p_WB: np.ndarray) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _advance(self, t: float) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _state(self):  # pragma: no cover - abstract
        raise NotImplementedError

    def _asleep(self) -> bool:
        return False


def smallest_width(scene: Scene) -> float:
    """The block size d the fall threshold is a fraction of (the smallest horizontal
    block edge, = BLOCK_SIZE for the cubes of the stimuli)."""
    if not len(scene):
        return BLOCK_SIZE
    return float(min(b.size[:2].min() for b in scene.blocks))


def layout_key(scene: Scene) -> str:
    """What a compiled model depends on: block sizes and the fixed boxes (not the
    block poses, which are set per run)."""
    h = digest(*(b.size for b in scene.blocks), *(part for f in scene.fixed for part in (f.p_WO, f.size)))
    return f"{len(scene)}:{h[:16]}"


def block_speeds(v_WB: np.ndarray, w_WB: np.ndarray, half_diagonals: np.ndarray) -> np.ndarray:
    """Upper bound of the speed of any point of each block: |v| + |w| * r, with r the
    half diagonal (v, w: (n, 3) linear and angular velocities; r from
    `half_diagonals`, computed once per layout)."""
    return row_norms(v_WB) + row_norms(w_WB) * half_diagonals


def half_diagonals(sizes: np.ndarray) -> np.ndarray:
    """Half the space diagonal of each block (sizes (n, 3), m), computed once per
    layout. Halving is exact in floating point, so |w| * (d / 2) equals (|w| * d) / 2
    to the bit: the speed bound does not depend on where the halving happens."""
    return row_norms(np.asarray(sizes, dtype=float).reshape(-1, 3)) / 2


def row_norms(x: np.ndarray) -> np.ndarray:
    """Euclidean norm of each row: what np.linalg.norm(x, axis=1) computes for a
    real array (the same ufuncs, so the same numbers), without its dispatch, which
    costs more than the arithmetic on a few blocks at every check of every run."""
    return np.sqrt(np.add.reduce(x * x, axis=1))


@dataclass(frozen=True)
class EngineSpec:
    """Where an engine lives ("module:Class", imported on first use, so MuJoCo runs
    do not pay for importing pydrake), the constructor's arguments, the package it
    needs (with how to install it), and whether it passes the faithfulness suite."""

    target: str
    kwargs: tuple = ()
    requires: str | None = None
    install: str | None = None
    faithful: bool = True


_PHYSX_INSTALL = 'pip install -e ".[physx]" (PhysX through the sapien package)'
#: Known engines by name. An engine's profile is part of its name: "physx" is the
#: faithful PhysX profile, "physx:game-defaults" the unfaithful one
#: (models/risk/physx_engine.py).
ENGINES = {
    "mujoco": EngineSpec("models.risk.mujoco_engine:MujocoEngine"),
    "drake": EngineSpec("models.risk.drake_engine:DrakeEngine"),
    "physx": EngineSpec("models.risk.physx_engine:PhysxEngine", (("profile", "faithful"),), "sapien", _PHYSX_INSTALL),
    "physx:game-defaults": EngineSpec("models.risk.physx_engine:PhysxEngine", (("profile", "game-defaults"),),
                                      "sapien", _PHYSX_INSTALL, faithful=False),
}
#: Profiles of engines that have several: engine -> {profile: engine name}.
PROFILES = {"physx": {"faithful": "physx", "game-defaults": "physx:game-defaults"}}
_INSTANCES: dict[str, Engine] = {}


class EngineUnavailableError(ValueError):
    """A known engine whose optional package is not installed."""


def engine_name(engine: str, profile: str | None = None) -> str:
    """The registry name of `engine` with `profile` (None: the engine's faithful
    one), checked: ValueError for an unknown engine or profile,
    EngineUnavailableError (saying how to install it) for a missing package."""
    name = engine
    if profile is not None:
        base = engine.split(":")[0]
        if base not in PROFILES and profile != "faithful":
            raise InputError(f"engine {engine!r} has one profile, faithful (other profiles are for: {', '.join(PROFILES)})")
        if base not in PROFILES:
            profile = None
        elif profile not in PROFILES[base]:
            raise InputError(f"unknown {base} profile {profile!r}; known profiles: {', '.join(PROFILES[base])}")
    if profile is not None:
        name = PROFILES[base][profile]
        if engine != base and engine != name:
            raise InputError(f"engine {engine!r} contradicts profile {profile!r}")
    if name not in ENGINES:
        raise InputError(f"unknown physics engine {engine!r}; known engines: {', '.join(ENGINES)}")
    spec = ENGINES[name]
    if spec.requires is not None:
        import importlib.util

        if importlib.util.find_spec(spec.requires) is None:
            raise EngineUnavailableError(f"engine {name!r} needs the {spec.requires} package, not installed: {spec.install}")
    return name


def available_engines() -> list[str]:
    """Names of the engines whose packages are installed."""
    out = []
    for name in ENGINES:
        try:
            out.append(engine_name(name))
        except EngineUnavailableError:
            pass
    return out


def get_engine(name: str) -> Engine:
    """The process-wide instance of the engine called `name`."""
    name = engine_name(name)
    if name not in _INSTANCES:
        import importlib

        spec = ENGINES[name]
        module, cls = spec.target.split(":")
        _INSTANCES[name] = getattr(importlib.import_module(module), cls)(**dict(spec.kwargs))
    return _INSTANCES[name]

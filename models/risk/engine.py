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

from lgp.geometry import digest
from lgp.paper import BLOCK_SIZE, DURATION
from lgp.scene import Scene

#: Wood (kg/m^3) and wood-on-wood friction, for blocks, table and fixed boxes.
DENSITY = 600.0
FRICTION = 0.6
#: A run falls when some block's centre ends farther than this (fraction of the
#: block size d) from where it started, measured in the horizontal plane.
FALL_THRESHOLD = 0.25
#: Early termination is checked every CHECK_INTERVAL s of simulated time: the run
#: stops as a fall once a block has moved FALL_CERTAIN * d horizontally (a rocking
#: tower can carry its top block past FALL_THRESHOLD * d and back), and as a stand
#: once every point of every block has moved slower than REST_SPEED for
#: REST_WINDOW s in a row without speeding up by more than REST_SLACK over that
#: window (a structure that starts to topple from rest speeds up slowly at first),
#: or once the engine has put every block to sleep.
FALL_CERTAIN = 1.0
CHECK_INTERVAL = 0.025
REST_SPEED = 0.005
REST_WINDOW = 0.3
REST_SLACK = 0.0002


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

    Subclass contract: `_load(scene)` (make the model for the scene's layout current
    and place its blocks at rest), `_advance(t)` (step to simulated time t),
    `_state()` -> (p_WB (n, 3), fastest point speed per block (n,)), and
    `_asleep()` -> True when the engine has put every block to sleep.
    """

    name = "?"

    def settings(self) -> dict:
        """Engine settings worth recording next to results."""
        return {}

    def simulate(self, scene: Scene, duration: float = DURATION, early_stop: bool = True) -> Rollout:
        """Run `scene` from rest for `duration` s (less with early termination)."""
        self._load(scene)
        p_start, _ = self._state()
        if not len(scene):
            return Rollout(p_start, p_start, 0.0, False)
        certain = FALL_CERTAIN * _smallest_width(scene)
        t, rest_since, rest_speed = 0.0, 0.0, np.inf
        n_checks = int(round(duration / CHECK_INTERVAL))
        for k in range(1, n_checks + 1):
            t = min(duration, k * CHECK_INTERVAL)
            self._advance(t)
            if not early_stop:
                continue
            p, speed = self._state()
            if np.max(np.linalg.norm(p[:, :2] - p_start[:, :2], axis=1)) > certain:
                return Rollout(p_start, p, t, t < duration)
            if self._asleep():
                return Rollout(p_start, p, t, t < duration)
            fastest = float(np.max(speed)) if len(speed) else 0.0
            if fastest >= REST_SPEED:
                rest_since, rest_speed = t, np.inf
            elif rest_speed == np.inf:
                rest_since, rest_speed = t, fastest
            elif t - rest_since >= REST_WINDOW - 1e-9:
                if fastest <= rest_speed + REST_SLACK:
                    return Rollout(p_start, p, t, t < duration)
                rest_since, rest_speed = t, fastest  # speeding up: watch again
        p, _ = self._state()
        return Rollout(p_start, p, t, False)

    # subclass hooks
    def _load(self, scene: Scene) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _advance(self, t: float) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _state(self):  # pragma: no cover - abstract
        raise NotImplementedError

    def _asleep(self) -> bool:
        return False


def _smallest_width(scene: Scene) -> float:
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


def block_speeds(v_WB: np.ndarray, w_WB: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Upper bound of the speed of any point of each block: |v| + |w| * r, with r the
    half diagonal (v, w: (n, 3) linear and angular velocities)."""
    return np.linalg.norm(v_WB, axis=1) + np.linalg.norm(w_WB, axis=1) * np.linalg.norm(sizes, axis=1) / 2


#: Known engines: name -> "module:Class" (imported on first use, so MuJoCo runs do
#: not pay for importing pydrake).
ENGINES = {
    "mujoco": "models.risk.mujoco_engine:MujocoEngine",
    "drake": "models.risk.drake_engine:DrakeEngine",
}
_INSTANCES: dict[str, Engine] = {}


def get_engine(name: str) -> Engine:
    """The process-wide instance of the engine called `name`."""
    if name not in ENGINES:
        raise ValueError(f"unknown physics engine {name!r}; known engines: {', '.join(sorted(ENGINES))}")
    if name not in _INSTANCES:
        import importlib

        module, cls = ENGINES[name].split(":")
        _INSTANCES[name] = getattr(importlib.import_module(module), cls)()
    return _INSTANCES[name]

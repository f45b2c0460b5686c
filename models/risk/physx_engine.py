"""PhysX 5 engine of the risk model, through the `sapien` package (CPU, no display;
optional extra: ``pip install -e ".[physx]"``). The paper simulated its noisy
scenes in PhysX; this engine lets a user see what the engine itself does to risk.

Two profiles, both written here and only here (docs/risk.md, "PhysX"):

- ``faithful`` (engine name ``physx``): settings measured on the faithfulness
  suite (tests/test_risk_engines.py): blocks at their true size (1 inch), a
  1 ms step, the TGS solver with 20 position iterations, contact offsets
  scaled to the block, no restitution.
- ``game-defaults`` (engine name ``physx:game-defaults``, UNFAITHFUL): PhysX as a
  scene author who keeps the engine's defaults would run it: blocks scaled to
  1 unit (1 m cubes, the scale of a game scene), SAPIEN/PhysX defaults for the
  step (0.01 s), the solver iterations (10 position, 1 velocity), the contact and
  rest offsets (0.01, 0), the sleep and bounce thresholds. It fails parts of the
  faithfulness suite (the failures are asserted in the tests with their numbers)
  and exists only to show how an engine's artefacts move risk; never a default.

Both profiles use the same material as the other engines (wood: density 600
kg/m^3, friction 0.6, no restitution), so they differ from them in numerics only.
Gravity is 9.81 m/s^2 in both; in ``game-defaults`` it acts on 1 m blocks, as it
would in a game scene built at that scale. Positions and speeds reported to the
rollout are in the stimulus's metres.

Unlike the other engines, every run builds a fresh PhysX scene (about 1 ms for
10 blocks): a reused scene carries PhysX's contact and solver caches from one
run to the next, so a chaotic run would depend on the runs before it.
"""
from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np

from lgp.errors import InputError
from lgp.geometry import quaternion_from_yaw
from lgp.paper import BLOCK_SIZE
from lgp.scene import Scene
from models.risk.engine import DENSITY, FRICTION, Engine, block_speeds, half_diagonals

INSTALL_HINT = 'the physx engine needs the optional extra: pip install -e ".[physx]" (the sapien package)'


@dataclass(frozen=True)
class PhysxSettings:
    """Everything that configures a PhysX profile (the values in docs/risk.md)."""

    profile: str
    #: stimulus metres -> simulated units (1: true size; 1 / d: 1-unit blocks)
    scale: float
    timestep: float
    enable_tgs: bool
    solver_position_iterations: int
    solver_velocity_iterations: int
    contact_offset: float  # in simulated units
    rest_offset: float
    sleep_threshold: float  # PhysX mass-normalised kinetic energy per unit mass
    bounce_threshold: float
    enable_pcm: bool = True
    enable_enhanced_determinism: bool = True
    restitution: float = 0.0
    friction: float = FRICTION
    density: float = DENSITY


#: The profiles by name. `faithful` values come from the faithfulness suite
#: (docs/risk.md, "PhysX"); `game-defaults` are SAPIEN 3 / PhysX 5 defaults.
PROFILES = {
    "faithful": PhysxSettings(
        profile="faithful", scale=1.0, timestep=0.001, enable_tgs=True,
        solver_position_iterations=20, solver_velocity_iterations=4,
        contact_offset=0.002, rest_offset=0.0, sleep_threshold=1e-6, bounce_threshold=0.2,
    ),
    "game-defaults": PhysxSettings(
        profile="game-defaults", scale=1.0 / BLOCK_SIZE, timestep=0.01, enable_tgs=True,
        solver_position_iterations=10, solver_velocity_iterations=1,
        contact_offset=0.01, rest_offset=0.0, sleep_threshold=0.005, bounce_threshold=2.0,
        enable_enhanced_determinism=False,
    ),
}
#: Profiles that pass the faithfulness suite.
FAITHFUL_PROFILES = ("faithful",)


def _import_sapien():
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "Failed to find system libvulkan": rendering only
            import sapien
    except ImportError as e:
        raise ImportError(INSTALL_HINT) from e
    return sapien


class _Layout:
    """One PhysX scene with a table, the fixed boxes and the blocks of a scene at
    their poses, at rest."""

    def __init__(self, sapien, scene: Scene, s: PhysxSettings):
        px = sapien.physx
        px.set_scene_config(
            bounce_threshold=s.bounce_threshold, enable_pcm=s.enable_pcm, enable_tgs=s.enable_tgs,
            enable_ccd=False, enable_enhanced_determinism=s.enable_enhanced_determinism,
            enable_friction_every_iteration=True,
        )
        px.set_shape_config(contact_offset=s.contact_offset, rest_offset=s.rest_offset)
        px.set_body_config(
            solver_position_iterations=s.solver_position_iterations,
            solver_velocity_iterations=s.solver_velocity_iterations, sleep_threshold=s.sleep_threshold,
        )
        self.system = px.PhysxCpuSystem()
        self.scene = sapien.Scene([self.system])
        self.scene.set_timestep(s.timestep)
        material = px.PhysxMaterial(s.friction, s.friction, s.restitution)
        k = s.scale
        table = self.scene.create_actor_builder()
        table.add_box_collision(half_size=(50 * BLOCK_SIZE * k,) * 2 + (BLOCK_SIZE * k,), material=material)
        table.set_initial_pose(sapien.Pose([0.0, 0.0, -BLOCK_SIZE * k]))
        table.build_static(name="table")
        for j, f in enumerate(scene.fixed):
            b = self.scene.create_actor_builder()
            b.add_box_collision(half_size=f.size * k / 2, material=material)
            b.set_initial_pose(sapien.Pose(f.p_WO * k))
            b.build_static(name=f"{f.name}_{j}")
        self.bodies = []
        for blk in scene.blocks:
            b = self.scene.create_actor_builder()
            b.add_box_collision(half_size=blk.size * k / 2, material=material, density=s.density)
            b.set_initial_pose(sapien.Pose(blk.p_WB * k, quaternion_from_yaw(np.array([blk.yaw]))[0]))
            entity = b.build(name=blk.name)
            self.bodies.append(entity.find_component_by_type(px.PhysxRigidDynamicComponent))
        self.scale = k


@dataclass
class PhysxEngine(Engine):
    """PhysX through SAPIEN with the settings of one profile (PROFILES)."""

    profile: str = "faithful"

    def __post_init__(self):
        if self.profile not in PROFILES:
            raise InputError(f"unknown PhysX profile {self.profile!r}; known profiles: {', '.join(PROFILES)}")
        self.config = PROFILES[self.profile]
        self.name = "physx" if self.profile == "faithful" else f"physx:{self.profile}"
        self._sapien = _import_sapien()

    def settings(self) -> dict:
        return {"engine": self.name, "version": self._sapien.__version__, "faithful": self.profile in FAITHFUL_PROFILES,
                **asdict(self.config)}

    def _load(self, scene: Scene, p_WB: np.ndarray) -> None:
        if not np.array_equal(p_WB, scene.positions):
            scene = scene.with_blocks(b.moved_to(p) for b, p in zip(scene.blocks, p_WB))
        # A fresh PhysX scene per run (1-2 ms for 10 blocks): a reused scene keeps
        # PhysX's contact and solver caches from run to run even after its state is
        # restored and its bodies are re-added, and chaotic runs then depend on
        # the runs before them (measured: up to 8 cm apart; docs/risk.md).
        self._L = _Layout(self._sapien, scene, self.config)
        self._half_diagonals = half_diagonals([b.size for b in scene.blocks])
        self._steps = 0
        self._last = None  # (step, p, q) of the last _state call

    def _advance(self, t: float) -> None:
        dt = self.config.timestep
        target = int(np.floor(t / dt + 0.5))
        while self._steps < target:
            self._L.scene.step()
            self._steps += 1

    def _state(self):
        """Block centres (m) and speeds. PhysX's reported velocities of resting
        blocks jitter at about g * timestep (6 mm/s at 1 ms, above REST_SPEED)
        while the blocks move by microns, so speeds are measured from the poses:
        the mean speed over the interval since the last call."""
        L, k = self._L, self._L.scale
        poses = [b.entity_pose for b in L.bodies]  # `.pose` is deprecated in sapien 3
        p = np.array([x.p for x in poses], dtype=float) / k
        q = np.array([x.q for x in poses], dtype=float)
        last, self._last = self._last, (self._steps, p, q)
        if last is None or last[0] == self._steps:
            v = np.array([b.linear_velocity for b in L.bodies], dtype=float) / k
            w = np.array([b.angular_velocity for b in L.bodies], dtype=float)
            return p, block_speeds(v, w, self._half_diagonals)
        dt = (self._steps - last[0]) * self.config.timestep
        angle = 2 * np.arccos(np.clip(np.abs(np.sum(q * last[2], axis=1)), 0.0, 1.0))
        return p, block_speeds((p - last[1]) / dt, angle[:, None] * [0, 0, 1] / dt, self._half_diagonals)

    def _asleep(self) -> bool:
        return all(b.is_sleeping for b in self._L.bodies)

"""Drake MultibodyPlant engine of the risk model.

Configuration (docs/risk.md, "Drake"): hydroelastic contact between compliant
boxes (modulus 1e9 Pa, margin 1e-5 m), triangle contact surfaces, the "lagged"
discrete approximation at a 1 ms time step, Hunt-Crossley dissipation 5000 s/m,
and a compliant slab as the table. Each choice is forced by a failure measured on
block stacks: point contact resolves box-on-box to a corner and topples stable
towers; polygon surfaces move the support edge inward and topple the x0.9
harmonic stack; a rigid half-space table makes blocks dropped a few mm slide or
blow up (and 3-D noise always drops some blocks); with Drake's default dissipation
lines never come to rest; at 10 ms a block dropped 4 mm starts a slow spurious
topple; at 5 ms and 2 ms a block dropping past a touching neighbour (a noisy
wall) is dragged off in 5-20% of runs.

The blocks of a scene's layout are written as an SDFormat model (free links)
and parsed by Drake's Parser; the table and fixed boxes are geometry of the world
body. One diagram and Simulator per layout are reused across runs.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from lgp.geometry import quaternion_from_yaw
from lgp.scene import Scene
from models.risk.engine import DENSITY, FRICTION, Engine, block_speeds, half_diagonals, layout_key


@dataclass(frozen=True)
class DrakeSettings:
    """Contact and integration settings of the Drake engine (defaults: the
    configuration that passes the faithfulness suite)."""

    time_step: float = 0.001
    hydroelastic_modulus: float = 1e9
    hydroelastic_margin: float = 1e-5
    hunt_crossley_dissipation: float | None = 5000.0  # s/m; None: Drake's default
    relaxation_time: float | None = None  # SAP only; None: Drake's default
    discrete_contact_approximation: str = "lagged"
    contact_surface_representation: str = "triangle"
    #: "halfspace": a rigid half-space z <= 0; "box": a compliant slab like the blocks
    table: str = "box"


DEFAULT_SETTINGS = DrakeSettings()

_PROXIMITY = """<drake:proximity_properties>
          {kind}
          <drake:mu_dynamic>{mu}</drake:mu_dynamic><drake:mu_static>{mu}</drake:mu_static>{extra}
        </drake:proximity_properties>"""


def _compliant(cfg: DrakeSettings) -> str:
    extra = (
        f"\n          <drake:hydroelastic_modulus>{cfg.hydroelastic_modulus:g}</drake:hydroelastic_modulus>"
        f"\n          <drake:hydroelastic_margin>{cfg.hydroelastic_margin:g}</drake:hydroelastic_margin>"
    )
    if cfg.hunt_crossley_dissipation is not None:
        extra += f"\n          <drake:hunt_crossley_dissipation>{cfg.hunt_crossley_dissipation:g}</drake:hunt_crossley_dissipation>"
    if cfg.relaxation_time is not None:
        extra += f"\n          <drake:relaxation_time>{cfg.relaxation_time:g}</drake:relaxation_time>"
    return _PROXIMITY.format(kind="<drake:compliant_hydroelastic/>", mu=FRICTION, extra=extra)


def sdformat(scene: Scene, cfg: DrakeSettings = DEFAULT_SETTINGS) -> str:
    """SDFormat text of the scene's layout (block poses are set per run)."""
    links = []
    for b in scene.blocks:
        sx, sy, sz = (float(c) for c in b.size)
        m = DENSITY * sx * sy * sz
        ixx, iyy, izz = m * (sy**2 + sz**2) / 12, m * (sx**2 + sz**2) / 12, m * (sx**2 + sy**2) / 12
        links.append(
            f"""    <link name="{b.name}">
      <inertial><mass>{m!r}</mass><inertia><ixx>{ixx!r}</ixx><iyy>{iyy!r}</iyy><izz>{izz!r}</izz>
        <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>
      <collision name="box"><geometry><box><size>{sx!r} {sy!r} {sz!r}</size></box></geometry>
        {_compliant(cfg)}
      </collision>
    </link>"""
        )
    return f"""<?xml version="1.0"?>
<sdf version="1.9" xmlns:drake="http://drake.mit.edu">
  <model name="blocks">
{chr(10).join(links)}
  </model>
</sdf>
"""


def _register_world_geometry(plant, scene: Scene, cfg: DrakeSettings) -> None:
    """The table (a compliant 2 m x 2 m x 10 cm slab under z = 0, or with
    cfg.table = "halfspace" a rigid half-space) and the fixed boxes (compliant, like
    the blocks) as collision geometry of the world body.

    Not in the SDFormat text: with drake 1.51.1, a parsed static or welded link plus
    14 or more free bodies segfaults in CreateDefaultContext (pair 12 has 20 blocks).
    """
    from pydrake.geometry import (
        AddCompliantHydroelasticProperties, AddContactMaterial, AddRigidHydroelasticProperties,
        Box, HalfSpace, ProximityProperties,
    )
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import CoulombFriction

    friction = CoulombFriction(FRICTION, FRICTION)

    def compliant(size):
        props = ProximityProperties()
        AddCompliantHydroelasticProperties(float(min(size)), cfg.hydroelastic_modulus, props)
        props.AddProperty("hydroelastic", "margin", float(cfg.hydroelastic_margin))
        AddContactMaterial(dissipation=cfg.hunt_crossley_dissipation, friction=friction, properties=props)
        if cfg.relaxation_time is not None:
            props.AddProperty("material", "relaxation_time", float(cfg.relaxation_time))
        return props

    world = plant.world_body()
    if cfg.table == "halfspace":
        table = ProximityProperties()
        AddRigidHydroelasticProperties(table)
        AddContactMaterial(friction=friction, properties=table)
        plant.RegisterCollisionGeometry(world, RigidTransform(), HalfSpace(), "table", table)
    else:
        size = (2.0, 2.0, 0.1)
        plant.RegisterCollisionGeometry(world, RigidTransform([0, 0, -size[2] / 2]), Box(*size), "table", compliant(size))
    for k, f in enumerate(scene.fixed):
        plant.RegisterCollisionGeometry(world, RigidTransform(f.p_WO), Box(*f.size), f"{f.name}_{k}", compliant(f.size))


class _Layout:
    """A built diagram for one layout, ready to be reset and run."""

    def __init__(self, scene: Scene, cfg: DrakeSettings):
        from pydrake.multibody.parsing import Parser
        from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        builder = DiagramBuilder()
        config = MultibodyPlantConfig(
            time_step=cfg.time_step,
            contact_model="hydroelastic",
            discrete_contact_approximation=cfg.discrete_contact_approximation,
            contact_surface_representation=cfg.contact_surface_representation,
        )
        plant, _ = AddMultibodyPlant(config, builder)
        Parser(plant).AddModelsFromString(sdformat(scene, cfg), "sdf")
        _register_world_geometry(plant, scene, cfg)
        plant.Finalize()
        diagram = builder.Build()
        self.plant = plant
        self.simulator = Simulator(diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        bodies = [plant.GetBodyByName(b.name) for b in scene.blocks]
        self.q_start = np.array([b.floating_positions_start() for b in bodies])
        self.v_start = np.array([b.floating_velocities_start_in_v() for b in bodies])
        self.nq, self.nv = plant.num_positions(), plant.num_velocities()


class DrakeEngine(Engine):
    name = "drake"

    def __init__(self, settings: DrakeSettings = DEFAULT_SETTINGS, **overrides):
        self.config = replace(settings, **overrides)
        self._layouts: dict[str, _Layout] = {}

    def settings(self) -> dict:
        from importlib.metadata import version

        return {"engine": "drake", "version": version("drake"), "contact_model": "hydroelastic", **asdict(self.config)}

    def _load(self, scene: Scene, p_WB: np.ndarray) -> None:
        key = layout_key(scene)
        if key not in self._layouts:
            self._layouts[key] = _Layout(scene, self.config)
        L = self._layouts[key]
        self._L = L
        q = np.zeros(L.nq)
        quat = quaternion_from_yaw([b.yaw for b in scene.blocks])
        for k in range(len(scene)):
            s = L.q_start[k]
            q[s : s + 4] = quat[k]
            q[s + 4 : s + 7] = p_WB[k]
        L.context.SetTime(0.0)
        L.plant.SetPositions(L.plant_context, q)
        L.plant.SetVelocities(L.plant_context, np.zeros(L.nv))
        L.simulator.Initialize()
        self._half_diagonals = half_diagonals([b.size for b in scene.blocks])

    def _advance(self, t: float) -> None:
        self._L.simulator.AdvanceTo(t)

    def _state(self):
        L = self._L
        q = L.plant.GetPositions(L.plant_context)
        v = L.plant.GetVelocities(L.plant_context)
        idx = L.q_start[:, None] + np.arange(4, 7)
        p = q[idx]
        w = v[L.v_start[:, None] + np.arange(0, 3)]
        lin = v[L.v_start[:, None] + np.arange(3, 6)]
        return p, block_speeds(lin, w, self._half_diagonals)

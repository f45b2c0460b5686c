"""MuJoCo engine of the risk model (settings from physics-notes.md, re-measured in
docs/risk.md): stiff, critically damped box contacts, pyramidal friction cone,
Newton solver, implicit-fast integration at 2 ms, and island sleeping."""
from __future__ import annotations

import numpy as np

from lgp.geometry import quaternion_from_yaw
from lgp.scene import Scene
from models.risk.engine import DENSITY, FRICTION, Engine, block_speeds, half_diagonals, layout_key

TIMESTEP = 0.002
SOLREF = "0.004 1"
SOLIMP = "0.95 0.99 0.001 0.5 2"

_MJCF = """<mujoco model="{name}">
  <option timestep="{timestep}" integrator="implicitfast" cone="pyramidal" solver="Newton"
          iterations="100" tolerance="1e-8">
    <flag sleep="{sleep}"/>
  </option>
  <default>
    <geom condim="3" friction="{friction} 0.005 0.0001" solref="{solref}" solimp="{solimp}"/>
  </default>
  <worldbody>
    <geom name="table" type="plane" size="0 0 1"/>
{fixed}
{blocks}
  </worldbody>
</mujoco>
"""


def mjcf(scene: Scene, sleep: bool = True) -> str:
    """MJCF text of the scene's layout; blocks sit at their poses in `scene`."""
    fixed = "\n".join(
        f'    <geom name="{f.name}_{k}" type="box" pos="{_v(f.p_WO)}" size="{_v(f.size / 2)}"/>'
        for k, f in enumerate(scene.fixed)
    )
    blocks = "\n".join(
        f'    <body name="{b.name}" pos="{_v(b.p_WB)}" euler="0 0 {b.yaw!r}">'
        f'<freejoint/><geom type="box" size="{_v(b.size / 2)}" density="{DENSITY}"/></body>'
        for b in scene.blocks
    )
    return _MJCF.format(
        name=scene.label, timestep=TIMESTEP, sleep="enable" if sleep else "disable", friction=FRICTION,
        solref=SOLREF, solimp=SOLIMP, fixed=fixed, blocks=blocks,
    )


#: MuJoCo's warnings in this process (most recent last, at most 100): kept here
#: instead of MuJoCo's default, which appends them to MUJOCO_LOG.TXT in the
#: current directory, i.e. the user's.
WARNINGS: list[str] = []


def _keep_warning(message: str) -> None:
    if len(WARNINGS) >= 100:
        del WARNINGS[0]
    WARNINGS.append(message)


def quiet_log(mj) -> None:
    """Route MuJoCo's warnings to `WARNINGS` (no MUJOCO_LOG.TXT in the cwd)."""
    mj.set_mju_user_warning(_keep_warning)


def _v(x) -> str:
    return " ".join(repr(float(c)) for c in x)


class MujocoEngine(Engine):
    name = "mujoco"

    def __init__(self, sleep: bool = True):
        import mujoco

        self._mj = mujoco
        quiet_log(mujoco)
        self.sleep = sleep
        self._models: dict[str, tuple] = {}
        self._scene = None

    def settings(self) -> dict:
        return {
            "engine": "mujoco", "version": self._mj.__version__, "timestep": TIMESTEP,
            "integrator": "implicitfast", "cone": "pyramidal", "solver": "Newton",
            "solref": SOLREF, "solimp": SOLIMP, "sleep": self.sleep,
        }

    def _load(self, scene: Scene, p_WB: np.ndarray) -> None:
        mj = self._mj
        if scene is not self._scene:  # the runs of a chunk share one (immutable) scene
            self._scene, self._key = scene, layout_key(scene)
            self._quat = quaternion_from_yaw([b.yaw for b in scene.blocks])
        key = self._key
        if key not in self._models:
            model = mj.MjModel.from_xml_string(mjcf(scene, self.sleep))
            data = mj.MjData(model)
            n = len(scene)
            # views into the state, made once per layout (the arrays live as long as data)
            radii = half_diagonals([b.size for b in scene.blocks])
            self._models[key] = (model, data, data.qpos.reshape(n, 7), data.qvel.reshape(n, 6), radii)
        m, d, self._qpos, self._qvel, self._half_diagonals = self._models[key]
        self.model, self.data = m, d
        mj.mj_resetData(m, d)
        self._qpos[:, :3] = p_WB
        self._qpos[:, 3:] = self._quat
        mj.mj_forward(m, d)

    def _advance(self, t: float) -> None:
        # as many steps as a one-step-at-a-time loop `while d.time < t - dt / 2` takes
        # (MuJoCo advances time by `time += timestep`, repeated here on the same
        # doubles), in one call, so the loop runs in C
        m, d = self.model, self.data
        dt = m.opt.timestep
        stop = t - 0.5 * dt
        time, steps = d.time, 0
        while time < stop:
            time += dt
            steps += 1
        if steps:
            self._mj.mj_step(m, d, steps)

    def _state(self):
        qvel = self._qvel
        return self._qpos[:, :3].copy(), block_speeds(qvel[:, :3], qvel[:, 3:], self._half_diagonals)

    def _asleep(self) -> bool:
        return self.sleep and int(self.data.ntree_awake) == 0

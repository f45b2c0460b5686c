"""A counterfactual fall measure on Mental Jenga scenes (stimuli/mental_jenga.py):
remove the black brick, perturb the remaining bricks, simulate, and count the red
bricks that fall off the table (the authors' criterion: centre below the fall line,
authors' y = 5, i.e. 0.018 m below the table top at SCALE 0.1).

One run follows the authors' protocol (code/js/brick_tools.js getNoiseResults):
the scene as read settles for 50 Box2D steps (here: PRESETTLE time, once per scene,
deterministic, with the black brick present), the black brick is removed, the
noise moves the other bricks, and the world runs for 700 steps of 1/60 s (11.7
authors' seconds, times `time_scale()` here) or until every brick rests; a brick
whose centre passes the fall line is taken out of the world, as Box2D's
`destroyDeadBricks` does. Bricks carry the authors' linear damping (1/s, scaled).

Noise rules (sigma from a grid; standard normals z drawn once per scene, shared by
every sigma: common random numbers). The noise moves the bricks the black brick
carries (directly or through others): the authors shift every brick but then put
to sleep those outside that set (`doSleepAbove` in brick_world.js), so a brick
elsewhere stays put until something falls on it. Rules ending in ":all" move
every remaining brick instead.
- "authors-x": every remaining brick moves along x only by sigma_A * z, sigma_A an
  absolute SD in the authors' length unit (their level k is sigma_A = 0.03 k).
- "paper-3d": the paper's rule: every remaining brick moves by sigma * size * z in
  its own frame (x, y, z axes; sigma a fraction of its edge along that axis).
Overlaps the noise creates are removed as the project's noise rule does
(models/risk/noise.py), on the bricks' x-z outlines (boxes around pitched bricks):
side neighbours are pushed apart along x, half each, to no more overlap than they
had; then, bottom-up, a brick is lifted to rest on what lies beneath its new
outline if the noise pushed it into it (the "lift" rule).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models.risk.engine import CHECK_INTERVAL, RestWatch, block_speeds, half_diagonals
from models.risk.mujoco_engine import SOLIMP, SOLREF, TIMESTEP, quiet_log
from models.risk.engine import DENSITY
from stimuli.mental_jenga import (FRICTION_A, LINEAR_DAMPING_A, PRESETTLE_STEPS_A, SETTLE_STEPS_A, STEP_A,
                                  JengaScene, time_scale)
from lgp.errors import InputError

NOISE_RULES = ("authors-x", "paper-3d", "authors-x:all", "paper-3d:all")
#: Two bricks touch when the gap between their x-z outlines is at most this
#: (authors' units; Box2D's skin, stimuli.mental_jenga.SKIN_A).
TOUCH_A = 0.02
#: Where removed and fallen bricks are parked (x, m): far from the table, on the ground.
PARK_X = 5.0
GRAVITY = 9.81


@dataclass(frozen=True)
class FallSettings:
    """How a run is simulated: the authors' linear damping on or off."""

    damping: bool = True

    def as_dict(self) -> dict:
        return {"damping": self.damping, "timestep": TIMESTEP, "solref": SOLREF, "solimp": SOLIMP,
                "presettle_steps_a": PRESETTLE_STEPS_A, "settle_steps_a": SETTLE_STEPS_A, "gravity": GRAVITY}


def _quat_y(theta: float) -> np.ndarray:
    return np.array([math.cos(theta / 2), 0.0, math.sin(theta / 2), 0.0])


def mjcf(scene: JengaScene) -> str:
    t = scene.table
    bodies = []
    for b in scene.bricks:
        q = _quat_y(b.pitch)
        bodies.append(f'    <body name="{b.name}" pos="{_v(b.p_WB)}" quat="{_v(q)}"><freejoint/>'
                      f'<geom type="box" size="{_v(b.size / 2)}" density="{DENSITY}"/></body>')
    return f"""<mujoco model="{scene.label}">
  <option timestep="{TIMESTEP}" gravity="0 0 {-GRAVITY}" integrator="implicitfast" cone="pyramidal" solver="Newton"
          iterations="100" tolerance="1e-8"><flag sleep="enable"/></option>
  <default><geom condim="3" friction="{FRICTION_A} 0.005 0.0001" solref="{SOLREF}" solimp="{SOLIMP}"/></default>
  <worldbody>
    <geom name="ground" type="plane" size="0 0 1"/>
    <geom name="table" type="box" pos="{_v(t.p_WO)}" size="{_v(t.size / 2)}" friction="{scene.table_friction} 0.005 0.0001"/>
{chr(10).join(bodies)}
  </worldbody>
</mujoco>
"""


def _v(x) -> str:
    return " ".join(repr(float(c)) for c in x)


class JengaWorld:
    """One compiled MuJoCo model of a scene, reused for every run."""

    def __init__(self, scene: JengaScene, settings: FallSettings = FallSettings()):
        import mujoco

        quiet_log(mujoco)
        self.mj, self.scene, self.settings = mujoco, scene, settings
        self.model = mujoco.MjModel.from_xml_string(mjcf(scene))
        self.data = mujoco.MjData(self.model)
        n = self.n = len(scene.bricks)
        self.qpos = self.data.qpos.reshape(n, 7)
        self.qvel = self.data.qvel.reshape(n, 6)
        self.radii = half_diagonals([b.size for b in scene.bricks])
        self.trees = self.model.body_treeid[1:].copy()  # kinematic tree of each brick (MuJoCo sleeps per tree)
        self.black = np.array([b.black for b in scene.bricks])
        self.ts = time_scale(scene.scale, GRAVITY)
        if settings.damping:  # Box2D's linearDamping: dv/dt = -c v on the linear dofs only
            mass = self.model.body_mass[1:]
            damp = self.model.dof_damping.reshape(n, 6)
            damp[:, :3] = (mass * LINEAR_DAMPING_A / self.ts)[:, None]
        self.duration = SETTLE_STEPS_A * STEP_A * self.ts
        self.q_settled = self._presettle()

    def _presettle(self) -> np.ndarray:
        mj, m, d = self.mj, self.model, self.data
        mj.mj_resetData(m, d)
        mj.mj_forward(m, d)
        self._step_to(PRESETTLE_STEPS_A * STEP_A * self.ts)
        return self.qpos.copy()

    def _step_to(self, t: float) -> None:
        m, d = self.model, self.data
        steps = 0
        time = d.time
        while time < t - 0.5 * m.opt.timestep:
            time += m.opt.timestep
            steps += 1
        if steps:
            self.mj.mj_step(m, d, steps)

    def settled_outlines(self):
        """Centres (n, 2: x, z), pitches and x-z half extents of the settled scene."""
        q = self.q_settled
        pitch = 2 * np.arctan2(q[:, 5], q[:, 3])
        c, s = np.abs(np.cos(pitch)), np.abs(np.sin(pitch))
        size = np.array([b.size for b in self.scene.bricks])
        half = np.stack([c * size[:, 0] / 2 + s * size[:, 2] / 2, s * size[:, 0] / 2 + c * size[:, 2] / 2], axis=1)
        return q[:, [0, 2]].copy(), pitch, half

    def _park(self, i: int) -> None:
        self.qpos[i, :3] = (PARK_X + 0.5 * i, 0.0, self.scene.bricks[i].size.max())
        self.qpos[i, 3:] = (1.0, 0.0, 0.0, 0.0)
        self.qvel[i] = 0.0

    def run(self, p_WB: np.ndarray | None = None) -> np.ndarray:
        """One counterfactual run: the settled scene, the black brick removed, the
        other bricks' centres at `p_WB` (n, 3; None: as settled). Returns (n,) bools,
        True for a brick that fell off the table (the black one is never counted)."""
        mj, m, d = self.mj, self.model, self.data
        mj.mj_resetData(m, d)
        self.qpos[:] = self.q_settled
        if p_WB is not None:
            self.qpos[:, :3] = p_WB
        fallen = np.zeros(self.n, bool)
        active = ~self.black
        for i in np.flatnonzero(self.black):
            self._park(i)
        mj.mj_forward(m, d)
        fall_z = self.scene.fall_z
        watch = RestWatch()
        n_checks = int(math.ceil(self.duration / CHECK_INTERVAL - 1e-9))
        for k in range(1, n_checks + 1):
            t = min(self.duration, k * CHECK_INTERVAL)
            self._step_to(t)
            below = active & (self.qpos[:, 2] < fall_z)
            if below.any():  # Box2D's destroyDeadBricks: out of the world
                for i in np.flatnonzero(below):
                    self._park(i)
                fallen |= below
                active &= ~below
                mj.mj_forward(m, d)
                watch.reset(t)
                continue
            if not active.any() or not self.data.tree_awake[self.trees[active]].any():
                break  # every brick still on the scene sleeps: nothing on it moves again (the parked ones are far away)
            speed = block_speeds(self.qvel[active, :3], self.qvel[active, 3:], self.radii[active])
            if watch.update(t, float(speed.max())):
                break
        return fallen


class PhysxJengaWorld:
    """The same counterfactual run in PhysX 5 (through sapien; the risk engine's
    faithful profile, models/risk/physx_engine.py: 1 ms steps, TGS with 20 position
    iterations, contact offset 2 mm, no restitution). The scene settles in PhysX
    (PRESETTLE time, black brick present); every run builds a fresh PhysX scene
    (a reused one carries contact caches from run to run) with the red bricks at
    the start given, and follows the MuJoCo world's protocol: the authors' linear
    damping, a brick whose centre passes the fall line is taken out and counted,
    the run stops at rest (RestWatch, speeds from poses between checks, as the
    risk engine measures them in PhysX) or when every brick on the scene sleeps.
    Same attributes as JengaWorld (n, scene, black, q_settled (n, 7: x y z, w x y z),
    settled_outlines), so Perturbation draws the same noise on it."""

    def __init__(self, scene: JengaScene, settings: FallSettings = FallSettings()):
        from models.risk.physx_engine import PROFILES, _import_sapien

        self.sapien, self.config = _import_sapien(), PROFILES["faithful"]
        self.scene, self.settings = scene, settings
        self.n = len(scene.bricks)
        self.black = np.array([b.black for b in scene.bricks])
        self.radii = half_diagonals([b.size for b in scene.bricks])
        self.ts = time_scale(scene.scale, GRAVITY)
        self.damping = LINEAR_DAMPING_A / self.ts if settings.damping else 0.0
        self.duration = SETTLE_STEPS_A * STEP_A * self.ts
        q0 = np.array([[*b.p_WB, *_quat_y(b.pitch)] for b in scene.bricks])
        bodies, step = self._build(q0, np.ones(self.n, bool))
        step(PRESETTLE_STEPS_A * STEP_A * self.ts)
        self.q_settled = self._poses(bodies)

    settled_outlines = JengaWorld.settled_outlines

    def _build(self, q: np.ndarray, present: np.ndarray):
        sapien, s = self.sapien, self.config
        px = sapien.physx
        px.set_scene_config(bounce_threshold=s.bounce_threshold, enable_pcm=s.enable_pcm, enable_tgs=s.enable_tgs,
                            enable_ccd=False, enable_enhanced_determinism=s.enable_enhanced_determinism,
                            enable_friction_every_iteration=True, gravity=[0.0, 0.0, -GRAVITY])
        px.set_shape_config(contact_offset=s.contact_offset, rest_offset=s.rest_offset)
        px.set_body_config(solver_position_iterations=s.solver_position_iterations,
                           solver_velocity_iterations=s.solver_velocity_iterations, sleep_threshold=s.sleep_threshold)
        world = sapien.Scene([px.PhysxCpuSystem()])
        world.set_timestep(s.timestep)
        brick = px.PhysxMaterial(FRICTION_A, FRICTION_A, s.restitution)
        t = self.scene.table
        for name, half, pos, mat in (("ground", (10.0, 10.0, 0.5), (0.0, 0.0, -0.5), brick),
                                     ("table", t.size / 2, t.p_WO, px.PhysxMaterial(self.scene.table_friction,
                                                                                   self.scene.table_friction, s.restitution))):
            b = world.create_actor_builder()
            b.add_box_collision(half_size=[float(v) for v in half], material=mat)
            b.set_initial_pose(sapien.Pose([float(v) for v in pos]))
            b.build_static(name=name)
        bodies = {}
        for i, brk in enumerate(self.scene.bricks):
            if not present[i]:
                continue
            b = world.create_actor_builder()
            b.add_box_collision(half_size=[float(v) for v in brk.size / 2], material=brick, density=DENSITY)
            b.set_initial_pose(sapien.Pose([float(v) for v in q[i, :3]], [float(v) for v in q[i, 3:]]))
            entity = b.build(name=brk.name)
            body = entity.find_component_by_type(px.PhysxRigidDynamicComponent)
            body.set_linear_damping(self.damping)
            body.set_angular_damping(0.0)
            bodies[i] = body
        steps = [0]

        def step_to(time: float) -> None:
            target = int(np.floor(time / s.timestep + 0.5))
            while steps[0] < target:
                world.step()
                steps[0] += 1

        self._world = world
        return bodies, step_to

    def _poses(self, bodies) -> np.ndarray:
        out = np.zeros((self.n, 7))
        for i, b in bodies.items():
            pose = b.entity_pose
            out[i, :3], out[i, 3:] = pose.p, pose.q
        return out

    def run(self, p_WB: np.ndarray | None = None) -> np.ndarray:
        """As JengaWorld.run: (n,) bools, True for a red brick that fell off the table."""
        q = self.q_settled.copy()
        if p_WB is not None:
            q[:, :3] = p_WB
        bodies, step_to = self._build(q, ~self.black)
        fallen = np.zeros(self.n, bool)
        fall_z = self.scene.fall_z
        watch = RestWatch()
        last = self._poses(bodies)
        n_checks = int(math.ceil(self.duration / CHECK_INTERVAL - 1e-9))
        for k in range(1, n_checks + 1):
            t = min(self.duration, k * CHECK_INTERVAL)
            step_to(t)
            now, prev = self._poses(bodies), last
            last = now
            below = [i for i in bodies if now[i, 2] < fall_z]
            if below:  # out of the world, counted
                for i in below:
                    bodies.pop(i).entity.remove_from_scene()
                    fallen[i] = True
                watch.reset(t)
                continue
            if not bodies or all(b.is_sleeping for b in bodies.values()):
                break
            idx = np.array(sorted(bodies))
            angle = 2 * np.arccos(np.clip(np.abs(np.sum(now[idx, 3:] * prev[idx, 3:], axis=1)), 0.0, 1.0))
            v = (now[idx, :3] - prev[idx, :3]) / CHECK_INTERVAL
            w = angle[:, None] * np.array([0.0, 0.0, 1.0]) / CHECK_INTERVAL
            if watch.update(t, float(block_speeds(v, w, self.radii[idx]).max())):
                break
        return fallen


from models.box2d_engine import Box2DJengaWorld, Box2DNoise  # noqa: E402 (pybox2d itself is imported when a world is made)
from models.box2dweb_engine import Box2DWebJengaWorld  # noqa: E402

#: The engines a counterfactual run can use, by name. "box2dweb" is the authors'
#: exact engine (box2dweb, Box2D 2.1a in JavaScript, through Node;
#: models/box2dweb_engine.py), "box2d" the same protocol in pybox2d (Box2D 2.3; the
#: optional extra `box2d`, models/box2d_engine.py), both in their 2-D world.
WORLDS = {"mujoco": JengaWorld, "physx": PhysxJengaWorld, "box2d": Box2DJengaWorld, "box2dweb": Box2DWebJengaWorld}
#: The 2-D engines: they draw the authors' noise (Box2DNoise), not Perturbation's rules.
WORLDS_2D = (Box2DJengaWorld, Box2DWebJengaWorld)


class Perturbation:
    """The noise rules on one settled scene (module docstring), vectorised over runs."""

    def __init__(self, world: JengaWorld):
        self.world = world
        scene = world.scene
        self.xz, self.pitch, self.half = world.settled_outlines()
        self.movable = ~world.black
        idx = np.flatnonzero(self.movable)
        self.idx = idx
        xz, half = self.xz, self.half
        tol = 1e-4 * scene.scale
        self.side, self.stack = [], []
        for a in range(len(idx)):
            for b in range(a + 1, len(idx)):
                i, j = idx[a], idx[b]
                zov = half[i, 1] + half[j, 1] - abs(xz[i, 1] - xz[j, 1])
                xov = half[i, 0] + half[j, 0] - abs(xz[i, 0] - xz[j, 0])
                if zov > tol:  # side neighbours: keep their order along x
                    sgn = 1.0 if xz[j, 0] >= xz[i, 0] else -1.0
                    self.side.append((i, j, sgn, max(0.0, xov)))
                else:  # one above the other: lower first
                    lo, hi = (i, j) if xz[i, 1] < xz[j, 1] else (j, i)
                    self.stack.append((lo, hi, max(0.0, zov)))
        t = scene.table
        self.table_top, self.table_x, self.table_hx = t.top, t.p_WO[0], t.size[0] / 2
        self.table_allow = np.maximum(0.0, self.table_top - (xz[:, 1] - half[:, 1]))
        self.order = idx[np.argsort(xz[idx, 1] - half[idx, 1], kind="stable")]
        self.above = self._above_black(TOUCH_A * scene.scale)

    def _above_black(self, touch: float) -> np.ndarray:
        """The bricks the black brick carries, directly or through others (the
        authors' "extended" contacts: "above_local", recursively): j is above i when
        their outlines overlap in x and j's bottom lies within `touch` of i's top, or
        (for a pitched brick, whose outline is a box around it) their outlines touch
        and j's centre is higher."""
        xz, half, n = self.xz, self.half, self.world.n
        pitched = np.abs(np.sin(self.pitch)) > 1e-6

        def above(i, j):
            xgap = abs(xz[i, 0] - xz[j, 0]) - half[i, 0] - half[j, 0]
            zgap = (xz[j, 1] - half[j, 1]) - (xz[i, 1] + half[i, 1])
            if pitched[i] or pitched[j]:
                return xgap <= touch and abs(xz[i, 1] - xz[j, 1]) - half[i, 1] - half[j, 1] <= touch and xz[j, 1] > xz[i, 1]
            return xgap < 0 and -touch <= zgap <= touch

        found = np.zeros(n, bool)
        queue = list(np.flatnonzero(self.world.black))
        while queue:
            i = queue.pop(0)
            for j in range(n):
                if not found[j] and not self.world.black[j] and above(i, j):
                    found[j] = True
                    queue.append(j)
        return found

    def positions(self, rule: str, sigma: float, z: np.ndarray) -> np.ndarray:
        """Centres (R, n, 3) for normals z (R, n, 3) at `sigma` (authors' units for
        "authors-x", a fraction of the edge for "paper-3d")."""
        world = self.world
        scene = world.scene
        R, n = z.shape[0], world.n
        p = np.repeat(world.q_settled[None, :, :3], R, axis=0).copy()
        if rule not in NOISE_RULES:
            raise InputError(f"unknown noise rule {rule!r}; known rules: {', '.join(NOISE_RULES)}")
        rule, _, scope = rule.partition(":")
        m = self.movable if scope == "all" else self.above
        if rule == "authors-x":
            p[:, m, 0] += scene.scale * sigma * z[:, m, 0]
        elif rule == "paper-3d":
            size = np.array([b.size for b in scene.bricks])
            local = sigma * size[None] * z  # body frame
            c, s = np.cos(self.pitch), np.sin(self.pitch)
            # R_y(pitch) @ local
            p[:, :, 0] += (c * local[:, :, 0] + s * local[:, :, 2]) * m
            p[:, :, 1] += local[:, :, 1] * m
            p[:, :, 2] += (-s * local[:, :, 0] + c * local[:, :, 2]) * m
        else:
            raise InputError(f"unknown noise rule {rule!r}; known rules: {', '.join(NOISE_RULES)}")
        if sigma == 0:
            return p
        half = self.half
        x = p[:, :, 0]
        for _ in range(500):  # side pairs: push apart along x, half each
            worst = 0.0
            for i, j, sgn, allow in self.side:
                gap = sgn * (x[:, j] - x[:, i]) - (half[i, 0] + half[j, 0] - allow)
                short = np.minimum(gap, 0.0)
                if short.any():
                    x[:, i] += sgn * short / 2
                    x[:, j] -= sgn * short / 2
                    worst = max(worst, float(-short.min()))
            if worst < 1e-12:
                break
        if rule == "paper-3d":  # lift, bottom-up
            zc = p[:, :, 2]
            over_table = np.abs(x - self.table_x) < half[:, 0] + self.table_hx
            floor = np.where(over_table, self.table_top + half[:, 1] - self.table_allow, half[:, 1])
            for i in self.order:
                need = floor[:, i].copy()
                for lo, hi, allow in self.stack:
                    if hi != i or not m[lo]:
                        continue
                    touch = np.abs(x[:, lo] - x[:, i]) < half[lo, 0] + half[i, 0]
                    need = np.where(touch, np.maximum(need, zc[:, lo] + half[lo, 1] + half[i, 1] - allow), need)
                zc[:, i] = np.maximum(zc[:, i], need)
        return p


def draw_normals(n_runs: int, n_bricks: int, seed: int, trial: int) -> np.ndarray:
    """Standard normals (runs, bricks, 3) of one scene: run r uses z[r] at every sigma."""
    return np.random.default_rng([seed, trial]).standard_normal((n_runs, n_bricks, 3))


def make_world(scene: JengaScene, settings: FallSettings = FallSettings(), engine: str = "mujoco"):
    """The scene settled in `engine` (WORLDS), ready for runs."""
    if engine not in WORLDS:
        raise InputError(f"unknown engine {engine!r} for the fall measure; known: {', '.join(WORLDS)}")
    return WORLDS[engine](scene, settings)


def counterfactual_runs(scene: JengaScene, rule: str, sigmas, n_runs: int, seed: int = 0,
                        settings: FallSettings = FallSettings(), engine: str = "mujoco"):
    """Tidy table: trial, rule, sigma, run, fallen (count of red bricks off the table), ids."""
    import pandas as pd

    world = make_world(scene, settings, engine)
    noise = Box2DNoise(world) if isinstance(world, WORLDS_2D) else Perturbation(world)
    z = draw_normals(n_runs, world.n, seed, scene.trial)
    rows = []
    names = [b.name for b in scene.bricks]
    done: dict[bytes, np.ndarray] = {}  # a run is a function of its start: equal starts are simulated once
    starts = [noise.positions(rule, float(sigma), z) for sigma in sigmas]
    if hasattr(world, "runs"):  # an engine that takes a batch (box2dweb: one Node process per scene)
        todo = {P[r].tobytes(): P[r] for P in starts for r in range(n_runs)}
        done = dict(zip(todo, world.runs(list(todo.values()))))
    for sigma, P in zip(sigmas, starts):
        for r in range(n_runs):
            key = P[r].tobytes()
            if key not in done:
                done[key] = world.run(P[r])
            f = done[key]
            rows.append((scene.label, rule, float(sigma), r, int(f.sum()), " ".join(nm for nm, x in zip(names, f) if x)))
    return pd.DataFrame(rows, columns=["trial", "rule", "sigma", "run", "fallen", "ids"])


def deterministic_falls(scene: JengaScene, settings: FallSettings = FallSettings(), engine: str = "mujoco") -> np.ndarray:
    """Which bricks fall when the black brick is removed and nothing else changes."""
    return make_world(scene, settings, engine).run()

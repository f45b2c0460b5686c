"""The counterfactual fall measure in the authors' own engine: Box2D (pybox2d, the
optional extra `box2d`), in the authors' 2-D world, units and frame (y points down),
following their code step for step. References are to the repository
`cicl-stanford/mental_jenga` (commit dc3bca49fa40), code/js/brick_world.js (BW) and
code/js/brick_tools.js (BT):

- world: gravity (0, 10), no automatic sleeping (BW 106: `new b2World(.., false)`);
  ground, left leg, right leg, table top, then the bricks in file order, created in
  that order (BW 118-124, 138-153); bricks 0.8 x 0.4 (half-extents 0.4, 0.2), density
  10, friction 0.6, restitution 0.2 (BW 49-64); table parts density 10, restitution
  0.2, friction 0.6 (1 in experiment 1, BT 50-53); ground friction 1, restitution 0
  (BW 118); every body linear damping 1 (BW 234);
- a step is `Step(1/60, 15, 5)` then `ClearForces` (BW 200-201), then the
  authors' own sleeping of every brick but the black one whose speed is below 5e-6
  and whose signed angular velocity is below 5e-6 (BW 293-304), then bricks whose
  centre is below y = 5 are destroyed (BW 273-290);
- one run (BT 54-78 `getNoiseResults`, BW 568-588 `loadData`, BW 330-465
  `removeBrick`/`applyNoise`): a fresh world, the scene loaded and settled for 50
  steps (`settle(50)`, BW 585; the empty world's `settle(100)` before the bricks
  exist, BW 126, moves nothing and is skipped), the bricks the black brick carries
  found from Box2D's contacts ("extended": "above_local" recursively, BW 468-565),
  with noise level > 0 every remaining brick shifted along x by 0.03 x level x N(0,1)
  and woken (BW 422-441), the black brick destroyed (BW 264-270, 368-375), and with
  noise the bricks outside the carried set put to sleep (`doSleepAbove`, BW 390-397;
  a sleeping brick stays where the noise put it until something touches it); then
  700 steps (`settle()`, SETTLE_TIME_DEFAULT, BW 35); the fallen are the bricks that
  were on the table before those steps and were destroyed during them.

Differences from the authors' run, stated: they used box2dweb (a JavaScript port of
Box2D 2.1a); pybox2d wraps Box2D 2.3.x (same solver family and constants, slop
0.005, restitution threshold 1 m/s; the two differ in details such as time-of-impact
handling), and their random numbers came from seedrandom(0) in one stream, ours
from numpy (models.counterfactual.draw_normals, common across sigma). A run stops
early when no brick is awake: a sleeping Box2D body does not move until an awake
one touches it, so the remaining steps would change nothing.
"""
from __future__ import annotations

import math

import numpy as np

from lgp.errors import InputError
from stimuli.mental_jenga import (BRICK_A, FALL_Y_A, FRICTION_A, GRAVITY_A, LINEAR_DAMPING_A, PRESETTLE_STEPS_A,
                                  SETTLE_STEPS_A, STEP_A, X_CENTRE_A, GROUND_Y_A, JengaScene)

#: The install hint, one line.
EXTRA_HINT = "the box2d engine needs pybox2d: pip install -e \".[box2d]\" (the project's optional extra `box2d`)"
VELOCITY_ITERATIONS, POSITION_ITERATIONS = 15, 5  # BW 200
SLEEP_SPEED_A = 0.000005  # BW 299
BRICK_DENSITY_A, BRICK_RESTITUTION_A = 10.0, 0.2  # BW 49, 52
TABLE_DENSITY_A, TABLE_RESTITUTION_A = 10.0, 0.2  # BW 68, 71
GROUND_FRICTION_A, GROUND_RESTITUTION_A = 1.0, 0.0  # BW 118
FULL_X_A, FULL_Y_A = 8.0, 6.0  # BW 41-42
NOISE_PER_LEVEL_A = 0.03  # BW 435
#: The noise rules this engine draws (the authors' own): "authors-x" shifts every
#: remaining brick along x and puts those the black brick does not carry to sleep,
#: as their perceptual noise does; "authors-x:all" leaves every brick awake.
RULES = ("authors-x", "authors-x:all")


#: The authors' world never puts a body to sleep by itself (BW 106, `doSleep` false);
#: pybox2d 2.3.10's b2World(doSleep=False) still does (measured: a brick resting on
#: the table sleeps after 29 steps), so each body is made with allowSleep False,
#: which keeps Box2D's own sleeping off and the authors' SetAwake(false) working.
NO_AUTO_SLEEP = True


def import_box2d():
    try:
        import Box2D
    except ImportError:
        raise InputError(EXTRA_HINT) from None
    return Box2D


def authors_xy(scene: JengaScene) -> np.ndarray:
    """(n, 3): the authors' x, y (down) and angle of each brick of the scene, from the
    project's frame (stimuli.mental_jenga.to_world inverted; the angle as read)."""
    s = scene.scale
    return np.array([[b.p_WB[0] / s + X_CENTRE_A, GROUND_Y_A - b.p_WB[2] / s, b.angle_a] for b in scene.bricks])


class Box2DJengaWorld:
    """One scene in Box2D, the authors' protocol (module docstring); a fresh world per
    run, as theirs. `run(start)` takes the start of models.counterfactual's noise:
    (n, 3) with column 0 the x shift of each brick (authors' units) and column 1 = 1
    where the authors' noise puts the uncarried bricks to sleep (None: no noise, the
    deterministic run). Attributes n, scene, black as the other engines'."""

    def __init__(self, scene: JengaScene, settings=None):
        self.b2 = import_box2d()
        import Box2D._Box2D as B

        self.B = B
        self.scene, self.settings = scene, settings
        self.n = len(scene.bricks)
        self.black = np.array([b.black for b in scene.bricks])
        self.xya = authors_xy(scene)
        self.table_friction = float(scene.table_friction)
        self.hw, self.hh = BRICK_A[0] / 2, BRICK_A[1] / 2
        self.carried = self._carried_by_black()

    # ------------------------------------------------------------------ the world

    def _box(self, world, hw, hh, x, y, angle, dynamic, density, friction, restitution, name):
        b2 = self.b2
        kind = b2.b2_dynamicBody if dynamic else b2.b2_staticBody
        body = world.CreateBody(b2.b2BodyDef(type=kind, position=(x, y), angle=angle, linearDamping=LINEAR_DAMPING_A,
                                            allowSleep=False))  # see NO_AUTO_SLEEP
        body.CreateFixture(b2.b2FixtureDef(shape=b2.b2PolygonShape(box=(hw, hh)), density=density,
                                           friction=friction, restitution=restitution))
        body.userData = name
        return body

    def load(self):
        """A fresh world with the scene loaded and settled (BW 103-127, 131-174, 568-588):
        (world, bodies {brick index: body}, alive set)."""
        b2 = self.b2
        world = b2.b2World(gravity=(0.0, GRAVITY_A), doSleep=False)
        cx = FULL_X_A / 2
        tf = self.table_friction
        self._box(world, cx, 0.1, cx, FULL_Y_A - 0.1, 0.0, False, 10.0, GROUND_FRICTION_A, GROUND_RESTITUTION_A, "ground")
        self._box(world, 0.1, 0.4, cx - 1, FULL_Y_A - 0.4 - 0.2, 0.0, False, TABLE_DENSITY_A, tf, TABLE_RESTITUTION_A, "left_leg")
        self._box(world, 0.1, 0.4, cx + 1, FULL_Y_A - 0.4 - 0.2, 0.0, False, TABLE_DENSITY_A, tf, TABLE_RESTITUTION_A, "right_leg")
        self._box(world, 1.5, 0.1, cx, FULL_Y_A - 0.1 - 0.80 - 0.18, 0.0, False, TABLE_DENSITY_A, tf, TABLE_RESTITUTION_A, "table")
        bodies = {}
        for i, (x, y, a) in enumerate(self.xya):
            bodies[i] = self._box(world, self.hw, self.hh, float(x), float(y), float(a), True, BRICK_DENSITY_A,
                                  FRICTION_A, BRICK_RESTITUTION_A, i)
        alive = dict(bodies)
        self._settle(world, alive, PRESETTLE_STEPS_A, stop_when_asleep=False)
        return world, bodies, alive

    def _settle(self, world, alive: dict, steps: int, stop_when_asleep: bool = True) -> None:
        """`steps` of BW 197-213: step, clear forces, the authors' sleeping, the dead
        destroyed. Only bricks awake after the step are looked at: with Box2D's own
        sleeping off, a brick asleep after a step was asleep before it and did not move
        (it was looked at when it last moved). SWIG's flat functions (B) are used, not
        pybox2d's properties: the same calls, half the time."""
        B = self.B
        awake, ang, vel, length, pos, set_awake = (B.b2Body___IsAwake, B.b2Body___GetAngularVelocity,
                                                   B.b2Body___GetLinearVelocity, B.b2Vec2___Length,
                                                   B.b2Body___GetPosition, B.b2Body___SetAwake)
        black = set(np.flatnonzero(self.black).tolist())
        for _ in range(steps):
            world.Step(STEP_A, VELOCITY_ITERATIONS, POSITION_ITERATIONS)
            world.ClearForces()
            moving = [(i, b) for i, b in alive.items() if awake(b)]
            for i, b in moving:
                if i not in black and ang(b) < SLEEP_SPEED_A and length(vel(b)) < SLEEP_SPEED_A:
                    set_awake(b, False)
            for i, b in moving:
                if pos(b)[1] > FALL_Y_A:
                    self._destroy(world, alive.pop(i))
            if stop_when_asleep and not moving:
                break  # nothing was awake after this step: the remaining steps change nothing

    @staticmethod
    def _destroy(world, body) -> None:
        """BW 264-270."""
        body.position = (-5.0, -5.0)
        body.linearVelocity = (0.0, 0.0)
        body.angularVelocity = 0.0
        body.active = False
        world.DestroyBody(body)

    # ------------------------------------------------------------------ contacts

    def _above_local(self, body) -> list:
        """BW 481-531, type "above_local": the bricks touching `body` that lie above it
        around the contact point."""
        out = []
        for edge in body.contacts:
            c = edge.contact
            n_pts = c.manifold.pointCount
            if n_pts == 0 or edge.other.type != self.b2.b2_dynamicBody:
                continue
            pts = c.worldManifold.points[:n_pts]
            pts = [p for p in pts if p[0] != 0 or p[1] != 0]
            if not pts:
                continue
            x = sum(p[0] for p in pts) / len(pts)
            y = sum(p[1] for p in pts) / len(pts)
            a = body.fixtures[0].TestPoint((x, y + 0.01))
            b = edge.other.fixtures[0].TestPoint((x, y - 0.01))
            if a or b:
                out.append(edge.other)
        return out

    def _carried_by_black(self) -> np.ndarray:
        """(n,) bools: the bricks the black brick carries after the settle ("extended",
        BW 532-546), the black one excluded; from one deterministic load."""
        world, bodies, alive = self.load()
        carried = np.zeros(self.n, bool)
        for k in np.flatnonzero(self.black):
            if k not in alive:
                continue
            found = [alive[k]]
            idx = 0
            while idx < len(found):
                for other in self._above_local(found[idx]):
                    if all(other is not f for f in found):
                        found.append(other)
                idx += 1
            for f in found[1:]:
                carried[f.userData] = True
        return carried & ~self.black

    # ------------------------------------------------------------------ a run

    def run(self, start: np.ndarray | None = None) -> np.ndarray:
        """One counterfactual run (module docstring). Returns (n,) bools, True for a
        red brick destroyed below the fall line during the 700 steps."""
        world, bodies, alive = self.load()
        black = np.flatnonzero(self.black)
        if start is not None and np.any(start[:, 0] != 0):
            for i, b in alive.items():  # BW 424-441
                if self.black[i]:
                    continue
                p = b.position
                b.position = (p[0] + float(start[i, 0]), p[1])
                b.awake = True
            sleep_uncarried = bool(np.any(start[:, 1] > 0))
        else:
            sleep_uncarried = False
        for k in black:
            if k in alive:
                self._destroy(world, alive.pop(k))
        if sleep_uncarried:  # BW 390-397
            for i, b in alive.items():
                if not self.carried[i]:
                    b.awake = False
        before = set(alive)
        self._settle(world, alive, SETTLE_STEPS_A)
        fallen = np.zeros(self.n, bool)
        fallen[list(before - set(alive))] = True
        return fallen & ~self.black


class Box2DNoise:
    """The authors' perceptual noise on a Box2D world, vectorised over runs: the
    start arrays Box2DJengaWorld.run takes."""

    def __init__(self, world: Box2DJengaWorld):
        self.world = world

    def positions(self, rule: str, sigma: float, z: np.ndarray) -> np.ndarray:
        """(R, n, 3) for normals z (R, n, 3) at `sigma` (authors' units: their level k
        is sigma = 0.03 k): column 0 the x shift sigma * z[..., 0] of every red brick,
        column 1 the flag of the authors' sleeping of uncarried bricks."""
        if rule not in RULES:
            raise InputError(f"noise rule {rule!r} is not drawn by the box2d engine (a 2-D world); "
                             f"its rules: {', '.join(RULES)}")
        R, n = z.shape[0], self.world.n
        out = np.zeros((R, n, 3))
        if sigma == 0:  # BW 412: level 0 adds no noise and sleeps nothing
            return out
        red = ~self.world.black
        out[:, red, 0] = sigma * z[:, red, 0]
        out[:, :, 1] = 0.0 if rule.endswith(":all") else 1.0
        return out

// The Mental Jenga counterfactual in the authors' own engine: box2dweb 2.1.0 (npm; the
// same file as their Box2dWeb-2.1.a.3.js, a JavaScript port of Box2D 2.1a) and, for
// the validation mode, their random numbers (seedrandom 3.0.5). A port of
// models/box2d_engine.py's protocol; references are to the repository
// cicl-stanford/mental_jenga (commit dc3bca49fa40), code/js/brick_world.js (BW) and
// code/js/brick_tools.js (BT).
//
//   node jenga.js < batch.json > result.json      (models/box2dweb_engine.py runs it)
//
// Input (JSON on stdin): {"early_stop": bool, "scenes": [scene, ...]}, a scene being
//   {"label": str, "bricks": [[x, y, angle], ...]  (the scene file's bricks in file
//    order, the authors' units, y down; parked ones, x = -5, included: BW 576-581
//    creates and then destroys them, which the broad-phase remembers),
//    "black": index, "table_friction": number, and either
//    "runs": [{"dx": [x shift per brick, file order], "sleep": bool}, ...]  (the
//      noise drawn by the Python side, models/box2d_engine.Box2DNoise), or
//    "authors_seed": {"levels": [k, ...], "runs": N}  (validation: the noise drawn
//      as their getNoiseResults draws it, seedrandom(0) reset per level, BT 45-48,
//      and BW applyNoise's gaussian and draw order, BW 411-441, 675-698)}.
// Output (JSON on stdout): {"scenes": [{"label", "fallen": [[file indices], ...]
//   (one list per run, in input order; authors_seed: level-major), "steps": total
//   Box2D steps taken after the removals}], "box2dweb": version, "seedrandom": version}.
'use strict';

const Box2D = require('box2dweb');
// npm's box2dweb 2.1.0 leaves out the last lines of the authors' Box2dWeb-2.1.a.3.js,
// which run the deferred definitions; without them b2ContactFactory crashes in Node.
if (Box2D.postDefs) {
  Box2D.postDefs.forEach((f) => f());
  delete Box2D.postDefs;
}
const seedrandom = require('seedrandom');

const b2Vec2 = Box2D.Common.Math.b2Vec2;
const b2BodyDef = Box2D.Dynamics.b2BodyDef;
const b2Body = Box2D.Dynamics.b2Body;
const b2FixtureDef = Box2D.Dynamics.b2FixtureDef;
const b2World = Box2D.Dynamics.b2World;
const b2PolygonShape = Box2D.Collision.Shapes.b2PolygonShape;
const b2WorldManifold = Box2D.Collision.b2WorldManifold;

const FULL_X = 8, FULL_Y = 6, CENTER_X = FULL_X / 2; // BW 41-43
const GRAVITY = 10; // BW 36
const SETTLE_STEPS = 700; // BW 35, SETTLE_TIME_DEFAULT
const LOAD_STEPS = 50; // BW 585
const EMPTY_STEPS = 100; // BW 126: the empty world's settle(100)
const BRICK_HW = 0.4, BRICK_HH = 0.2; // BW 54-55 (half-extents)
const BRICK_DENSITY = 10, BRICK_FRICTION = 0.6, BRICK_RESTITUTION = 0.2; // BW 49-52
const TABLE_DENSITY = 10, TABLE_RESTITUTION = 0.2; // BW 68, 71
const SLEEP_SPEED = 0.000005; // BW 299
const FALL_Y = 5; // BW 279
const PARKED_X = -5; // BW 578
const NOISE_PER_LEVEL = 0.03; // BW 435

// One fixture definition for every brick, as BW 58-64.
const brickFixDef = new b2FixtureDef();
brickFixDef.density = BRICK_DENSITY;
brickFixDef.friction = BRICK_FRICTION;
brickFixDef.restitution = BRICK_RESTITUTION;
brickFixDef.shape = new b2PolygonShape();
brickFixDef.shape.SetAsBox(BRICK_HW, BRICK_HH);

// BW 216-261 createBox.
function createBox(world, hw, hh, x, y, angle, type, density, friction, restitution, data, fixDef) {
  if (!fixDef) {
    fixDef = new b2FixtureDef();
    fixDef.density = density;
    fixDef.friction = friction;
    fixDef.restitution = restitution;
    fixDef.shape = new b2PolygonShape();
    fixDef.shape.SetAsBox(hw, hh);
  }
  const bodyDef = new b2BodyDef();
  bodyDef.type = type;
  bodyDef.position.x = x;
  bodyDef.position.y = y;
  bodyDef.angle = angle;
  bodyDef.linearDamping = 1; // BW 234
  const b = world.CreateBody(bodyDef);
  b.CreateFixture(fixDef);
  b.SetUserData(data);
  return b;
}

// BW 264-270 destroyBrick.
function destroyBrick(world, brick) {
  brick.SetPosition(new b2Vec2(-5, -5));
  brick.SetLinearVelocity(new b2Vec2(0, 0));
  brick.SetAngularVelocity(0);
  brick.SetActive(false);
  world.DestroyBody(brick);
}

// The authors' BrickWorld, reduced to what a fall-ids run calls (BT 54-78).
class Run {
  constructor(scene) {
    this.scene = scene;
    this.special = scene.black;
    // BW 103-127 setupWorld: no automatic sleeping (the `false`), ground, legs, top
    const world = (this.world = new b2World(new b2Vec2(0, GRAVITY), false));
    const tf = scene.table_friction;
    createBox(world, CENTER_X, 0.1, CENTER_X, FULL_Y - 0.1, 0, b2Body.b2_staticBody, 10, 1, 0, 'ground');
    createBox(world, 0.1, 0.4, CENTER_X - 1, FULL_Y - 0.4 - 0.2, 0, b2Body.b2_staticBody, TABLE_DENSITY, tf, TABLE_RESTITUTION, 'left_leg');
    createBox(world, 0.1, 0.4, CENTER_X + 1, FULL_Y - 0.4 - 0.2, 0, b2Body.b2_staticBody, TABLE_DENSITY, tf, TABLE_RESTITUTION, 'right_leg');
    createBox(world, 1.5, 0.1, CENTER_X, FULL_Y - 0.1 - 0.80 - 0.18, 0, b2Body.b2_staticBody, TABLE_DENSITY, tf, TABLE_RESTITUTION, 'table');
    for (let j = 0; j < EMPTY_STEPS; j++) {
      world.Step(1 / 60, 15, 5);
      world.ClearForces();
    }
    // BW 131-174 generateBrickPositions, 568-588 loadData
    this.bricks = scene.bricks.map((b, i) =>
      createBox(world, BRICK_HW, BRICK_HH, b[0], b[1], b[2], b2Body.b2_dynamicBody, BRICK_DENSITY, BRICK_FRICTION, BRICK_RESTITUTION, i, brickFixDef));
    this.live = new Set(this.bricks); // bricks_array_set less the destroyed (BW 173, 287)
    for (const b of this.bricks) {
      if (b.GetPosition().x === PARKED_X) {
        destroyBrick(world, b);
        this.live.delete(b); // never looked at again: its y stays -5 (BW 279)
      }
    }
    this.steps = 0; // steps taken after the removal
    this.settle(LOAD_STEPS, false);
  }

  // BW 197-213 settle: step, clear forces, the authors' sleeping (BW 293-304), the
  // dead destroyed (BW 273-290). With earlyStop, the steps end once a step leaves
  // every brick asleep and none moved during it: Collide then sees the positions it
  // saw in that step, wakes nothing, and no later step changes anything. Returns
  // the number of steps taken.
  settle(steps, earlyStop) {
    const world = this.world;
    let prev = earlyStop ? this.poses() : null;
    for (let j = 0; j < steps; j++) {
      world.Step(1 / 60, 15, 5);
      world.ClearForces();
      let anyAwake = false;
      for (const brick of this.live) {
        if (brick.IsAwake() && brick.GetUserData() !== this.special) {
          const vel = brick.GetLinearVelocity().Length();
          const angvel = brick.GetAngularVelocity(); // signed, as BW 298-299
          if (vel < SLEEP_SPEED && angvel < SLEEP_SPEED) {
            brick.SetAwake(false);
          }
        }
      }
      const dead = [];
      for (const brick of this.live) {
        if (brick.GetPosition().y > FALL_Y) dead.push(brick);
      }
      for (const brick of dead) {
        this.live.delete(brick);
        destroyBrick(world, brick);
      }
      if (earlyStop) {
        for (const brick of this.live) anyAwake = anyAwake || brick.IsAwake();
        const now = this.poses();
        if (!anyAwake && dead.length === 0 && samePoses(prev, now)) return j + 1;
        prev = now;
      }
    }
    return steps;
  }

  poses() {
    const out = [];
    for (const b of this.live) {
      const p = b.GetPosition();
      out.push(p.x, p.y, b.GetAngle());
    }
    return out;
  }

  // BW 320-327 getGoodBricks
  goodBricks() {
    return this.bricks.filter((b) => b.IsActive());
  }

  // BW 481-531, type "above_local": the bricks touching `brick` that lie above it
  // around the contact point.
  aboveLocal(brick) {
    const out = [brick];
    for (let edge = brick.GetContactList(); edge != null; edge = edge.next) {
      const wm = new b2WorldManifold();
      edge.contact.GetWorldManifold(wm);
      const pts = wm.m_points;
      let xsum = 0, ysum = 0, nonzeronum = 0;
      for (let i = 0; i < 2; i++) {
        if (pts[i].x !== 0 || pts[i].y !== 0) {
          xsum += pts[i].x;
          ysum += pts[i].y;
          nonzeronum++;
        }
      }
      if (nonzeronum !== 0 && edge.other.GetType() === 2) {
        const xval = xsum / nonzeronum, yval = ysum / nonzeronum;
        const brickA = brick.GetFixtureList().TestPoint(new b2Vec2(xval, yval + 0.01));
        const brickB = edge.other.GetFixtureList().TestPoint(new b2Vec2(xval, yval - 0.01));
        if (brickA || brickB) out.push(edge.other);
      }
    }
    return out;
  }

  // BW 532-546, type "extended": "above_local" recursively, breadth first; the
  // black brick first.
  extended(brick) {
    const list = [brick];
    for (let idx = 0; idx < list.length; idx++) {
      for (const b of this.aboveLocal(list[idx])) {
        if (list.indexOf(b) === -1) list.push(b);
      }
    }
    return list;
  }

  // BW 330-408 removeBrick with perceptual noise (BW 411-441): every good brick but
  // the black one shifted along x by dx(brick, k) and woken, the black brick
  // destroyed, then (sleep) the good bricks outside the extended set put to sleep.
  // dx null: no noise (level 0, BW 412).
  remove(dx, sleep) {
    const world = this.world;
    const theBrick = this.bricks[this.special];
    const extended = this.extended(theBrick);
    let sleepAbove = false;
    if (dx !== null) {
      let k = 0;
      for (const brick of this.goodBricks()) {
        if (brick === theBrick) continue;
        sleepAbove = sleep;
        const p = brick.GetPosition();
        brick.SetPosition(new b2Vec2(p.x + dx(brick.GetUserData(), k++), p.y));
        brick.SetAwake(true);
      }
    }
    destroyBrick(world, theBrick); // BW 368 (unconditionally, as theirs)
    this.live.delete(theBrick);
    if (sleepAbove) {
      for (const b of this.goodBricks()) {
        if (extended.indexOf(b) < 0) b.SetAwake(false);
      }
    }
  }

  // BT 67-77, "fall-ids": the bricks on the table before the settle and destroyed during it.
  fallIds(earlyStop) {
    const before = this.goodBricks();
    this.steps += this.settle(SETTLE_STEPS, earlyStop);
    return before.filter((b) => !b.IsActive()).map((b) => b.GetUserData());
  }
}

function samePoses(a, b) {
  if (a.length !== b.length) return false;
  for (let i = 0; i < a.length; i++) if (a[i] !== b[i]) return false;
  return true;
}

// BW 675-698 gaussian_gen: Marsaglia's polar method on `random`, pairs kept.
function gaussianGen(mean, stdev, random) {
  let y2;
  let useLast = false;
  return function () {
    let y1;
    if (useLast) {
      y1 = y2;
      useLast = false;
    } else {
      let x1, x2, w;
      do {
        x1 = 2.0 * random() - 1.0;
        x2 = 2.0 * random() - 1.0;
        w = x1 * x1 + x2 * x2;
      } while (w >= 1.0);
      w = Math.sqrt((-2.0 * Math.log(w)) / w);
      y1 = x1 * w;
      y2 = x2 * w;
      useLast = true;
    }
    return mean + stdev * y1;
  };
}

function runScene(scene, earlyStop) {
  const fallen = [];
  let steps = 0;
  const one = (dx, sleep) => {
    const run = new Run(scene); // a fresh world per run, as BT 55
    run.remove(dx, sleep);
    fallen.push(run.fallIds(earlyStop));
    steps += run.steps;
  };
  if (scene.authors_seed) {
    for (const level of scene.authors_seed.levels) {
      const random = seedrandom(0); // BT 47, per call of getNoiseResults
      for (let r = 0; r < scene.authors_seed.runs; r++) {
        if (level === 0) {
          one(null, false);
        } else {
          const gauss = gaussianGen(0, level, random); // a fresh generator per removal (BW 416)
          one(() => NOISE_PER_LEVEL * gauss(), true); // BW 435
        }
      }
    }
  } else {
    for (const r of scene.runs) {
      const noisy = r.dx.some((v) => v !== 0);
      one(noisy ? (i) => r.dx[i] : null, noisy && r.sleep);
    }
  }
  return { label: scene.label, fallen, steps };
}

function main() {
  const chunks = [];
  process.stdin.on('data', (c) => chunks.push(c));
  process.stdin.on('end', () => {
    const batch = JSON.parse(Buffer.concat(chunks).toString('utf8'));
    const out = {
      scenes: batch.scenes.map((s) => runScene(s, Boolean(batch.early_stop))),
      box2dweb: require('box2dweb/package.json').version,
      seedrandom: require('seedrandom/package.json').version,
    };
    process.stdout.write(JSON.stringify(out));
  });
}

if (require.main === module) main();

module.exports = { runScene };

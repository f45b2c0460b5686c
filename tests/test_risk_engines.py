"""Faithfulness of the physics engines behind the physical-risk model: textbook
stability answers, the static centre-of-mass criterion, and agreement between
the engines on the same noisy scenes (docs/risk.md, "Engines")."""
import functools

import numpy as np
import pytest

from lgp.scene import BLOCK_SIZE
from models.risk import ENGINES, UnstableSceneError, available_engines, check_stable, get_engine
from models.risk.model import DEFAULT_MODEL
from models.risk.noise import draw_normals, perturb_from_normals
from models.risk.static import static_margins, static_stable
from models.risk.structures import bridge, grid, harmonic, line, pyramid, staircase, tower, two_block

D = BLOCK_SIZE
INSTALLED = available_engines()
#: The suite runs on every installed engine. Faithful engines must pass all of it;
#: the unfaithful profile physx:game-defaults runs it too, and each of its failures
#: is asserted as an expected failure (strict: a pass is reported as an error),
#: with the numbers measured on this suite (docs/risk.md, "PhysX").
GAME = "physx:game-defaults"
GAME_FAILURES = {
    "early": "early termination changes 1 of 40 verdicts (13 falls early-stopped vs 14 in full 4-s runs)",
}


def engines(names=None, failure=None):
    """pytest params: the installed engines among `names` (default: all); an
    unfaithful engine is an expected failure when `failure` (a key of
    GAME_FAILURES) names its measured failure of the test."""
    out = []
    for name in names or list(ENGINES):
        if name not in INSTALLED:
            continue
        marks = ()
        if not ENGINES[name].faithful and failure is not None:
            marks = pytest.mark.xfail(strict=True, reason=f"{name} (unfaithful): {GAME_FAILURES[failure]}")
        out.append(pytest.param(name, marks=marks, id=name))
    return out


def falls(scene, engine, early_stop=True) -> bool:
    rollout = get_engine(engine).simulate(scene, early_stop=early_stop)
    return bool(rollout.horizontal_displacement().max() > DEFAULT_MODEL.fall_distance(scene))


def _falls(item) -> bool:
    return falls(*item)


def fall_verdicts(scenes, engine, early_stop=True) -> list[bool]:
    """falls() of each scene, in order. Drake's (seconds per scene) are simulated on
    both cores: the same verdicts as one after another, since a run does not depend
    on the runs before it (test_a_run_does_not_depend_on_the_runs_before_it).
    `early_stop`: one flag for all, or one per scene."""
    flags = early_stop if isinstance(early_stop, list) else [early_stop] * len(scenes)
    items = [(s, engine, bool(e)) for s, e in zip(scenes, flags, strict=True)]
    if engine != "drake" or len(items) < 2:
        return [falls(*item) for item in items]
    from lgp.executor import ProcessExecutor

    with ProcessExecutor(2) as executor:
        return executor.map(_falls, items)


# ----------------------------------------------------------------------------- analytic answers


@pytest.mark.parametrize("engine", engines())
@pytest.mark.parametrize("offset", [0.3, 0.45])
def test_block_overhanging_less_than_half_its_width_stands(engine, offset):
    check_stable(two_block(offset), engine)
    check_stable(two_block(offset, axis=1), engine)


@pytest.mark.parametrize("engine", engines())
@pytest.mark.parametrize("offset", [0.55, 0.7])
def test_block_overhanging_more_than_half_its_width_falls(engine, offset):
    with pytest.raises(UnstableSceneError, match=r"two-block offset .* block b1 moved"):
        check_stable(two_block(offset), engine)


@pytest.mark.parametrize("engine", engines())
def test_harmonic_overhang_stands_inside_and_falls_outside_the_critical_stack(engine):
    check_stable(harmonic(5, 0.9), engine)
    with pytest.raises(UnstableSceneError):
        check_stable(harmonic(5, 1.1), engine)


@pytest.mark.parametrize("engine", engines())
@pytest.mark.parametrize("scene", [tower(10), line(10), bridge(), pyramid(), staircase(4)], ids=lambda s: s.label)
def test_unperturbed_structures_stand(engine, scene):
    rollout = check_stable(scene, engine)
    assert rollout.horizontal_displacement().max() < 0.05 * D


@pytest.mark.parametrize("engine", engines())
def test_blocks_dropped_onto_their_supports_stay_put(engine):
    """3-D noise lifts blocks; a block landing from a few mm must not slide off
    (a rigid half-space table in Drake fails this: docs/risk.md)."""
    base = tower(6)
    lifted = base.with_blocks(b.moved_to(b.p_WB + [0, 0, 0.002 * k]) for k, b in enumerate(base.blocks))
    spread = line(10, gap=0.01)
    rng = np.random.default_rng(0)
    dropped = spread.with_blocks(b.moved_to(b.p_WB + [0, 0, rng.uniform(0.001, 0.004)]) for b in spread.blocks)
    for scene in (lifted, dropped):
        rollout = get_engine(engine).simulate(scene)
        assert rollout.horizontal_displacement().max() < 0.1 * D, scene.label


# ----------------------------------------------------------------------------- static criterion


def test_static_criterion_on_textbook_stacks():
    assert static_stable(two_block(0.45)) and not static_stable(two_block(0.55))
    assert static_stable(harmonic(5, 0.9)) and not static_stable(harmonic(5, 1.1))
    assert min(static_margins(two_block(0.3)).values()) == pytest.approx(0.2 * D)
    assert static_stable(tower(10)) and static_stable(line(10)) and static_stable(staircase(4, 0.2))
    assert not static_stable(staircase(4, 0.4))  # top three blocks' COM 0.6 d past the base's centre


def random_stack(rng, label):
    n = int(rng.integers(2, 5))
    offsets = rng.uniform(-0.6 * D, 0.6 * D, size=(n - 1, 2)) * rng.uniform(0, 1, size=(n - 1, 1))
    return tower(n, offsets=offsets, label=label)


def random_stacks(count, seed, ambiguity=0.04 * D):
    """Random 2-4 block stacks, half standing and half not by the static criterion,
    away from its boundary by `ambiguity` (a soft-contact engine moves the tipping
    edge inward by a fraction of a mm)."""
    rng = np.random.default_rng(seed)
    stand, fall = [], []
    while len(stand) + len(fall) < count:
        s = random_stack(rng, f"random stack {len(stand) + len(fall)}")
        margin = min(static_margins(s).values())
        if abs(margin) > ambiguity:
            bucket = stand if margin > 0 else fall
            if len(bucket) < count // 2 + count % 2 * (margin > 0):
                bucket.append(s)
    return stand + fall


@pytest.mark.parametrize("engine,count", [p for p in [("mujoco", 40), ("drake", 10), ("physx", 40), (GAME, 40)] if p[0] in INSTALLED])
def test_engine_agrees_with_static_criterion_on_random_stacks(engine, count):
    stacks = random_stacks(count, seed=2)
    verdicts = [(s.label, fell, not static_stable(s)) for s, fell in zip(stacks, fall_verdicts(stacks, engine))]
    assert any(v[2] for v in verdicts) and not all(v[2] for v in verdicts)  # both kinds present
    wrong = [v for v in verdicts if v[1] != v[2]]
    assert not wrong, f"{engine} disagrees with the static criterion on {wrong}"


# ----------------------------------------------------------------------------- noisy scenes


@functools.lru_cache(maxsize=None)
def noisy_scenes() -> tuple:
    """Perturbed copies of structures with a middling risk, so that both verdicts
    occur, and of a wall of touching blocks (Drake's weak spot: docs/risk.md)."""
    out = []
    cases = ((staircase(4), 0.1, 14), (staircase(3, 0.3), 0.08, 10), (tower(6), 0.1, 8), (grid(1, 3, 3), 0.1, 8))
    for scene, sigma, n in cases:
        for z in draw_normals(n, len(scene), seed=4):
            out.append(perturb_from_normals(scene, sigma, z))
    return tuple(out)


_NOISY_VERDICTS: dict[tuple, bool] = {}


def noisy_verdicts(engine, indices, early_stop=True) -> list[bool]:
    """falls() of the noisy scenes `indices` (with or without early termination),
    each simulated once per module and engine: the agreement, early-termination and
    sleeping checks judge the same rollouts (a run does not depend on the runs
    before it: test_a_run_does_not_depend_on_the_runs_before_it)."""
    scenes = noisy_scenes()
    todo = [k for k in indices if (engine, k, early_stop) not in _NOISY_VERDICTS]
    for k, fell in zip(todo, fall_verdicts([scenes[k] for k in todo], engine, early_stop)):
        _NOISY_VERDICTS[(engine, k, early_stop)] = fell
    return [_NOISY_VERDICTS[(engine, k, early_stop)] for k in indices]


#: Agreement on noisy scenes, calibrated: these chaotic scenes (middling risk) put
#: faithful engines at odds on a few percent of them (MuJoCo and Drake 2 of 40,
#: PhysX variants 2-4 of 40: docs/risk.md, "PhysX"). The claim is that an engine
#: disagrees with MuJoCo on at most AGREE_CLAIM of such scenes; the test fails when
#: the count of disagreements would have probability below FALSE_FAILURE under it.
AGREE_CLAIM = 0.05
FALSE_FAILURE = 1e-3


def allowed_disagreements(n, p=AGREE_CLAIM, alpha=FALSE_FAILURE) -> int:
    """The fewest disagreements k among n scenes with P(more than k) <= alpha when each
    scene disagrees independently with probability p: 1 - the binomial CDF at k."""
    from math import comb

    k, cdf = 0, (1 - p) ** n
    while 1 - cdf > alpha:
        k += 1
        cdf += comb(n, k) * p**k * (1 - p) ** (n - k)
    return k


def test_allowed_disagreements_is_the_binomial_tail_bound():
    """Closed form for n = 40, p = 5%: P(D >= 7) = 3.4e-3 > 1e-3 >= P(D >= 8) = 7.1e-4,
    summed here over the upper tail term by term; the old bound (D <= 2, "95% of 40") failed an engine
    at the claim's boundary with probability P(D >= 3) = 0.32."""
    from math import comb

    tail = lambda k: sum(comb(40, j) * 0.05**j * 0.95 ** (40 - j) for j in range(k, 41))  # noqa: E731
    assert allowed_disagreements(40) == 7
    assert tail(8) <= 1e-3 < tail(7)
    assert tail(8) == pytest.approx(7.1e-4, rel=0.01) and tail(3) == pytest.approx(0.32, abs=0.005)


#: The agreement check in two stages (a group-sequential design): first every other
#: noisy scene (20 of 40, half of each structure's runs); at most EARLY_PASS
#: disagreements there pass the engine, else all 40 are judged against
#: allowed_disagreements(40) as before. Its error rates, exactly
#: (test_the_two_stage_agreement_check_keeps_the_error_rates_of_the_40_scene_check):
#: an engine at the claim's boundary (95%) fails with probability 7.0e-4 (7.1e-4 with
#: all 40), one at 70% passes with 0.058 (0.055), and an engine that disagrees on 5%
#: (2.5%) of scenes stops after the first stage with probability 0.74 (0.91).
STAGE_1 = range(0, 40, 2)
EARLY_PASS = 1


def staged_agreement(a, b, stage_1=STAGE_1, early_pass=EARLY_PASS):
    """(disagreements, scenes judged) of two engines' verdicts on the noisy scenes,
    `a` and `b` callables of a list of scene indices -> verdicts: the first stage's
    scenes, and every scene only when that stage holds more than `early_pass`."""
    first = list(stage_1)
    d1 = int(np.sum(np.array(a(first)) != np.array(b(first))))
    if d1 <= early_pass:
        return d1, len(first)
    every = list(range(len(noisy_scenes())))
    return int(np.sum(np.array(a(every)) != np.array(b(every)))), len(every)


def test_the_two_stage_agreement_check_keeps_the_error_rates_of_the_40_scene_check():
    """Closed forms of the staged design, summed term by term over the binomial:
    P(pass) = P(D1 <= 1) + sum over d1 > 1 of P(D1 = d1) P(D2 <= 7 - d1), D1 ~ B(20, p)
    and D2 ~ B(20, p) the disagreements in the two halves."""
    from math import comb

    def pmf(n, k, p):
        return comb(n, k) * p**k * (1 - p) ** (n - k)

    def passes(p, k=allowed_disagreements(40)):
        early = sum(pmf(20, d, p) for d in range(EARLY_PASS + 1))
        return early + sum(pmf(20, d1, p) * sum(pmf(20, d2, p) for d2 in range(k - d1 + 1))
                           for d1 in range(EARLY_PASS + 1, k + 1))

    fixed = lambda p: sum(pmf(40, d, p) for d in range(allowed_disagreements(40) + 1))  # noqa: E731
    assert 1 - passes(AGREE_CLAIM) == pytest.approx(7.0e-4, rel=0.01) and 1 - passes(AGREE_CLAIM) <= FALSE_FAILURE
    assert 1 - passes(AGREE_CLAIM) <= 1 - fixed(AGREE_CLAIM)  # never fails a faithful engine more often
    assert passes(0.30) == pytest.approx(0.058, abs=5e-4) and fixed(0.30) == pytest.approx(0.055, abs=5e-4)
    assert sum(pmf(20, d, 0.05) for d in range(EARLY_PASS + 1)) == pytest.approx(0.74, abs=0.005)
    assert sum(pmf(20, d, 0.025) for d in range(EARLY_PASS + 1)) == pytest.approx(0.91, abs=0.005)
    # the procedure: a first stage over the limit judges all 40 scenes
    truth = {k: k % 2 == 0 for k in range(40)}
    same, flipped = (lambda ks: [truth[k] for k in ks]), (lambda ks: [not truth[k] if k in (0, 2) else truth[k] for k in ks])
    assert staged_agreement(same, same) == (0, 20)
    assert staged_agreement(same, flipped) == (2, 40)
    assert staged_agreement(same, flipped, early_pass=2) == (2, 20)


@pytest.mark.slow  # the noisy scenes in two engines
@pytest.mark.parametrize("other", engines(["drake", "physx", GAME]))
def test_engines_agree_on_the_same_noisy_scenes(other):
    """The noisy scenes judged by MuJoCo and by `other`, in two stages
    (staged_agreement): at most allowed_disagreements(40) = 7 verdicts of the 40
    differ, or at most EARLY_PASS of the first stage's 20. An engine that agrees with
    MuJoCo on 95% of such scenes (the claim's boundary) fails with probability 7.0e-4,
    one at 70% (the unfaithful Drake settings of docs/risk.md: 31-53%) passes with
    probability 0.058 (test_the_two_stage_agreement_check_keeps_the_error_rates_of_the_40_scene_check)."""
    mujoco = noisy_verdicts("mujoco", STAGE_1)
    assert 0 < sum(mujoco) < len(mujoco), "the check needs both falls and stands"
    wrong, judged = staged_agreement(lambda ks: noisy_verdicts("mujoco", ks), lambda ks: noisy_verdicts(other, ks))
    limit = EARLY_PASS if judged == len(STAGE_1) else allowed_disagreements(judged)
    assert wrong <= limit, (
        f"engines disagree on {wrong} of {judged} noisy scenes: P(>= {wrong}) < {FALSE_FAILURE:g} if they disagreed "
        f"on {AGREE_CLAIM:.0%}")


#: Which noisy scenes each engine runs in full 4 s: every one (MuJoCo, PhysX), or in
#: Drake (seconds per full run: 4-6 CPU-s for a 3-block staircase, 10-13 for the
#: 4-staircase and 6-tower) a standing 4-staircase and a falling and a standing
#: 3-staircase (MuJoCo's verdicts). Their early-stopped runs are the agreement check's.
EARLY_STOP_SCENES = {"mujoco": range(40), "drake": (12, 14, 18), "physx": range(40), GAME: range(40)}


@pytest.mark.parametrize("engine", [pytest.param(*p.values, marks=[*p.marks, pytest.mark.slow] if p.values[0] == "physx" else p.marks,
                                                 id=p.id) for p in engines(list(EARLY_STOP_SCENES), failure="early")])  # physx: ~15 s
def test_early_termination_gives_the_verdict_of_the_full_four_seconds(engine):
    which = list(EARLY_STOP_SCENES[engine])
    early, full = noisy_verdicts(engine, which), noisy_verdicts(engine, which, early_stop=False)
    assert early == full


def test_mujoco_sleeping_does_not_change_verdicts():
    from models.risk.mujoco_engine import MujocoEngine

    awake = MujocoEngine(sleep=False)
    asleep = noisy_verdicts("mujoco", range(20))
    for s, fell in zip(noisy_scenes()[:20], asleep):
        r = awake.simulate(s)
        assert (r.horizontal_displacement().max() > DEFAULT_MODEL.fall_distance(s)) == fell, s.label


@pytest.mark.parametrize("engine", engines())
def test_a_run_does_not_depend_on_the_runs_before_it(engine):
    """Models are reused across runs: reset must leave no trace of the last run."""
    scene = noisy_scenes()[3]
    eng = get_engine(engine)
    first = eng.simulate(scene)
    eng.simulate(two_block(0.7, label="two-block offset 0.7d"))  # a different layout that falls
    eng.simulate(noisy_scenes()[5])  # same layout, other poses
    again = eng.simulate(scene)
    np.testing.assert_array_equal(first.p_WB_final, again.p_WB_final)
    assert first.sim_time == again.sim_time


@pytest.mark.slow  # a fresh interpreter
def test_mujoco_warnings_do_not_write_a_log_into_the_users_directory(tmp_path):
    """MuJoCo's default appends warnings to MUJOCO_LOG.TXT in the current directory;
    the engine keeps them in memory instead (models.risk.mujoco_engine.WARNINGS)."""
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    script = textwrap.dedent("""
        import mujoco
        from models.risk import get_engine
        from models.risk.mujoco_engine import WARNINGS
        get_engine("mujoco")
        xml = ('<mujoco><worldbody><body pos="0 0 1e300"><freejoint/>'
               '<geom type="box" size="1e300 1 1"/></body></worldbody></mujoco>')
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        mujoco.mj_step(m, d)  # a huge value: MuJoCo warns
        assert any("unstable" in w for w in WARNINGS), WARNINGS
    """)
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True,
                          env={**__import__("os").environ, "PYTHONPATH": str(root)})
    assert done.returncode == 0, done.stderr
    assert list(tmp_path.iterdir()) == []

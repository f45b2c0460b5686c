"""The "settle" noise rule (docs/risk.md, "Noise rule"): the same
horizontal noise and side-pair separation as "lift", but every block set to rest
on what lies beneath its new outline, so no block starts in the air and what
falls is what topples. The 10-tower under "settle" is checked against a
centre-of-mass estimate computed here, not by the project's code."""
import numpy as np
import pytest
from scipy.stats import norm

import stimuli
from lgp.paper import BLOCK_SIZE as D
from lgp.scene import CONTACT_TOLERANCE
from models.risk import RiskModel, draw_normals, perturb_from_normals, physical_risk
from models.risk.core import wilson_interval
from models.risk.noise import NOISE_RULES, NoiseRule
from models.risk.structures import tower
from tests.test_risk_noise import SCENES


def _corners(p, size, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    hx, hy = size[0] / 2, size[1] / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return p[:2] + local @ np.array([[c, s], [-s, c]])


def _clip(poly, a, b):
    """Sutherland-Hodgman: the part of convex polygon `poly` left of edge a->b."""
    out = []
    side = lambda q: (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])  # noqa: E731
    for k in range(len(poly)):
        p, q = poly[k], poly[(k + 1) % len(poly)]
        sp, sq = side(p), side(q)
        if sp >= 0:
            out.append(p)
        if sp * sq < 0:
            out.append(p + (q - p) * (sp / (sp - sq)))
    return out


def _area(poly):
    if len(poly) < 3:
        return 0.0
    x, y = np.array(poly).T
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _overlap_area(P, Q):
    poly = list(P)
    for k in range(4):
        poly = _clip(poly, Q[k], Q[(k + 1) % 4])
        if not poly:
            return 0.0
    return _area(poly)


def air_gaps(before, after):
    """Per block of the noisy scene `after`: how far (m) its bottom is above the
    highest solid beneath its outline (solids beneath it in B `before`, or the table)."""
    solids0 = list(before.blocks) + list(before.fixed)
    solids = list(after.blocks) + list(after.fixed)
    outline = [_corners(np.asarray(o.p_WB if hasattr(o, "p_WB") else o.p_WO, float), o.size,
                        getattr(o, "yaw", 0.0)) for o in solids]
    gaps = []
    for i, b in enumerate(after.blocks):
        rest = min(0.0, before.blocks[i].bottom)
        for j, o in enumerate(solids):
            if j != i and solids0[j].top <= before.blocks[i].bottom + CONTACT_TOLERANCE \
                    and _overlap_area(outline[i], outline[j]) > 1e-12:
                rest = max(rest, o.top - max(0.0, solids0[j].top - before.blocks[i].bottom))
        gaps.append(b.bottom - rest)
    return np.array(gaps)


SETTLE_SCENES = SCENES + [stimuli.load_trial(t).target for t in ("7H", "4H", "5H", "8H", "12H", "3E")]


@pytest.mark.parametrize("scene", SETTLE_SCENES, ids=lambda s: s.label)
def test_under_settle_no_block_starts_above_its_support(scene):
    z = draw_normals(20, len(scene), 3)
    for sigma in (0.065, 0.15, 0.3):
        for r in range(len(z)):
            noisy = perturb_from_normals(scene, sigma, z[r], "settle")
            gaps = air_gaps(scene, noisy)
            assert gaps.max() <= CONTACT_TOLERANCE, f"{scene.label} sigma {sigma} run {r}: a block starts {gaps.max() * 1e3:.2f} mm up"
            assert gaps.min() >= -1e-9, f"{scene.label}: a block starts inside its support"


def test_under_lift_the_top_of_a_ten_tower_starts_in_the_air():
    """The contrast that makes the test above able to fail: the default rule
    leaves blocks millimetres above their supports."""
    scene = tower(10)
    z = draw_normals(20, len(scene), 3)
    gaps = np.array([air_gaps(scene, perturb_from_normals(scene, 0.065, z[r], "lift")).max() for r in range(20)])
    assert np.median(gaps) > 1e-3


@pytest.mark.parametrize("scene", SETTLE_SCENES, ids=lambda s: s.label)
def test_settle_keeps_the_horizontal_noise_of_lift(scene):
    z = draw_normals(10, len(scene), 5)
    lift = NoiseRule(scene, "lift").positions(0.1, z)
    settle = NoiseRule(scene, "settle").positions(0.1, z)
    np.testing.assert_array_equal(lift[..., :2], settle[..., :2])
    assert np.all(settle[..., 2] <= lift[..., 2] + 1e-15)  # settling only ever lowers a lifted block
    np.testing.assert_array_equal(NoiseRule(scene, "settle").positions(0.0, z), np.broadcast_to(scene.positions, z.shape))


def test_unknown_noise_rule_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match="unknown noise rule 'drop'; known rules: lift, settle"):
        NoiseRule(tower(3), "drop")
    with pytest.raises(ValueError, match="known rules: lift, settle"):
        physical_risk(tower(3), 0.065, n_sims=2, model=RiskModel(noise_rule="drop"))
    assert NOISE_RULES == ("lift", "settle")


# --------------------------------------------------------------------------- centre-of-mass estimate


def com_estimate(sigma, levels=10):
    """P(a 10-tower topples) by the static criterion, to first order: per axis the
    load above level k (m blocks) sits off block k's centre by the mean offset of
    the m blocks minus block k's, sd sigma d sqrt(1 + 1/m); the level tips when
    that exceeds d/2. Union over the 9 levels and 2 axes (an upper bound, and
    nearly exact when the probability is small)."""
    return sum(2 * 2 * norm.sf(0.5 / (sigma * np.sqrt(1 + 1 / m))) for m in range(1, levels))


def com_monte_carlo(sigma, n=200_000, levels=10, seed=11):
    """The same static criterion by Monte Carlo over independent offsets (units of d)."""
    x = np.random.default_rng(seed).standard_normal((n, levels, 2)) * sigma
    fell = np.zeros(n, bool)
    for k in range(levels - 1):
        fell |= (np.abs(x[:, k + 1:].mean(axis=1) - x[:, k]) > 0.5).any(axis=1)
    return fell.mean()


def test_centre_of_mass_closed_form_and_its_monte_carlo_agree():
    for sigma in (0.10, 0.12):
        p, mc = com_estimate(sigma), com_monte_carlo(sigma)
        se = np.sqrt(p * (1 - p) / 200_000)
        assert abs(mc - p) < 4 * se + 0.02 * p, (sigma, p, mc)
    assert com_estimate(0.065) < 1e-6  # the paper's sigma: a 10-tower practically never topples


@pytest.mark.slow  # 100 settled runs
def test_ten_tower_risk_under_settle_at_the_papers_sigma_is_the_centre_of_mass_estimate():
    scene = stimuli.load_trial("7H").target
    assert len(scene) == 10
    _, runs = physical_risk(scene, 0.065, n_sims=100, seed=0, model=RiskModel(noise_rule="settle"), return_table=True)
    falls = int(runs["fell"].sum())
    low, high = wilson_interval(falls, 100)
    estimate = com_estimate(0.065)
    assert low <= estimate <= high, f"7H settle: {falls}/100 falls, interval [{low:.3f}, {high:.3f}], estimate {estimate:.1e}"

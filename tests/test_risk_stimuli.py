"""Physical risk on the 24 stimuli: every Finish state B stands unperturbed, and
the paper's easy/hard contrasts in risk at its fitted sigma = 0.065 d."""
import pytest

from lgp.paper import PAPER_SIGMA as SIGMA  # the paper's fitted noise level (Results)
from conftest import distinct_b_trials
from lgp.paper import TRIAL_IDS
from models.risk import ENGINES, available_engines, check_stable, risk_table


#: MuJoCo (the default engine) on all 24 trials; a second faithful engine (Drake,
#: PhysX: slow) on each distinct B once (17 structures: conftest.same_b_as names the
#: copies, the same blocks at the same or a moved place on the table).
CASES = [(tid, e) for e in available_engines() if ENGINES[e].faithful
         for tid in (TRIAL_IDS if e == "mujoco" else distinct_b_trials())]


@pytest.mark.parametrize("trial_id, engine", CASES)
def test_unperturbed_finish_state_stands(trials, trial_id, engine):
    check_stable(trials[trial_id].target, engine)  # raises UnstableSceneError naming the block


#: The contrasts below simulate 8 trials x 100 runs (~6 s on 2 idle cores): slow.
contrast = pytest.mark.slow


@pytest.fixture(scope="module")
def risk_at_paper_sigma(trials):
    pairs = [t for t in trials.values() if t.pair in (4, 5, 7, 8)]
    table = risk_table(pairs, [SIGMA], n_sims=100, seed=0)
    return dict(zip(table["trial"], table["risk"]))


def assert_harder_is_riskier(risk, pair):
    e, h = risk[f"{pair}E"], risk[f"{pair}H"]
    assert h > e, f"risk at sigma = {SIGMA} d: {pair}H {h:.2f} vs {pair}E {e:.2f}"


@contrast
def test_tower_is_riskier_than_line(risk_at_paper_sigma):
    assert_harder_is_riskier(risk_at_paper_sigma, 7)


@contrast
def test_staircase_is_riskier_than_aligned_tower(risk_at_paper_sigma):
    assert_harder_is_riskier(risk_at_paper_sigma, 4)


@contrast
def test_bridge_is_riskier_than_pyramid(risk_at_paper_sigma):
    assert_harder_is_riskier(risk_at_paper_sigma, 5)


@contrast
@pytest.mark.xfail(
    strict=True,
    reason="measured with mujoco, n = 100, seed 0: 8H 0.00 vs 8E 0.00 at sigma 0.065 d (8H 0.08 vs 8E 0.00 at "
    "0.10 d); the castle is robust to the paper's fitted noise in a faithful engine (docs/risk.md)",
)
def test_castle_is_riskier_than_piles(risk_at_paper_sigma):
    assert_harder_is_riskier(risk_at_paper_sigma, 8)

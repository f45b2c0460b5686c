"""Plan views (lgp.app.view) and the results page's pure parts (lgp.app.page)."""
from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

import stimuli
from lgp.paper import BUILD_SITE
from lgp.app.view import CAMERA_FOV, camera_frame, order_colours, placement_order
from models.effort import cumulative_effort, kinetic_energy, kinetic_energy_by_action, plan_of_sample


@pytest.fixture(scope="module")
def tower():
    return plan_of_sample(stimuli.load_trial("7H"), 0, 0)


def test_effort_so_far_adds_up_to_every_action_and_to_the_plan(tower):
    cum = cumulative_effort(tower)
    S = int(round(1.0 / tower.tau))  # slices per 1 s phase
    at_ends = cum[[S * k for k in range(1, len(tower.actions) + 1)]]
    assert np.allclose(at_ends, np.cumsum(kinetic_energy_by_action(tower)), rtol=1e-12, atol=1e-15)
    assert cum[-1] == pytest.approx(kinetic_energy(tower), rel=1e-12)
    assert np.all(np.diff(cum) >= 0)


def test_a_tower_is_coloured_bottom_up_each_block_its_own_colour(tower):
    order = placement_order(tower)
    assert len(order) == 10
    z_final = [tower.p_WB[name][-1, 2] for name in order]
    assert np.all(np.diff(z_final) > 0)  # placed in the order they stack
    colours = order_colours(tower)
    rgb = np.array([colours[name] for name in order])
    assert len({tuple(np.round(c, 3)) for c in rgb}) == 10
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722])
    assert np.all(np.diff(luminance) > 0)  # a sequential colormap: later is lighter


def test_unmoved_blocks_are_grey_and_not_in_the_order():
    plan = plan_of_sample(stimuli.load_trial("9E"), 0, 0)  # half-built tower: 4 blocks stay
    order = placement_order(plan)
    colours = order_colours(plan)
    still = [b.name for b in plan.initial.blocks if b.name not in order]
    assert len(still) == 4 and len(order) == 2
    assert all(np.ptp(colours[name]) < 0.05 for name in still)


@pytest.mark.parametrize("trial_id", ["2H", "7H", "10H", "12E"])
def test_the_camera_sees_the_build_site_the_blocks_and_the_hand(trial_id):
    plan = plan_of_sample(stimuli.load_trial(trial_id), 0, 0)
    p_WC, p_WT = camera_frame(plan)
    axis = (p_WT - p_WC) / np.linalg.norm(p_WT - p_WC)
    points = [np.array([*BUILD_SITE, 0.0])] + [p[i] for p in plan.p_WB.values() for i in (0, -1)]
    for p in points:
        ray = (p - p_WC) / np.linalg.norm(p - p_WC)
        # inside the vertical field of view (the horizontal one is wider at 1280x800)
        assert np.degrees(np.arccos(np.clip(ray @ axis, -1, 1))) < CAMERA_FOV / 2


def test_pair_verdicts_mark_where_the_paper_and_we_differ():
    import math

    from analysis.pairs import pair_verdicts as verdicts
    from lgp.app.page import pair_verdicts

    inf = math.inf
    pairs = pd.DataFrame({  # the Eq. 1 columns of analysis.pairs.pair_orderings
        "pair": [4, 6, 11, 7],
        "eq1_ratio_low": [1.14, 0.0, 0.0, -inf], "eq1_ratio_high": [inf, 0.0, 0.0, inf],
        "eq1_tie": [False, True, False, False],
    })
    n = verdicts(pairs).set_index("pair")
    assert n["paper_ordered"].to_dict() == {4: True, 6: True, 11: False, 7: True}
    assert n["ordered"].to_dict() == {4: True, 6: False, 11: False, 7: True}
    assert n["differs"].to_dict() == {4: False, 6: True, 11: False, 7: False}
    v = pair_verdicts(pairs).set_index("pair")  # the page's words for them
    assert v.loc[4, "ours (Eq. 1)"] == "E < H for b2/b1 > 1.14" and not v.loc[4, "differs"]
    assert v.loc[6, "ours (Eq. 1)"] == "tie" and v.loc[6, "differs"]  # the paper ordered pair 6
    assert v.loc[11, "ours (Eq. 1)"] == "not ordered" and not v.loc[11, "differs"]  # nor did it order 11
    assert v.loc[7, "ours (Eq. 1)"] == "E < H for any b2/b1" and not v.loc[7, "differs"]


def test_the_pair_table_ties_by_the_one_rule():
    """A pair tied in effort and risk under analysis.pairs.TIE_REL is tied by Eq. 1
    (eq1_tie), and one just outside it is not: one rule for pairs.csv and the page."""
    from analysis.pairs import TIE_REL, pair_orderings
    from lgp.paper import TRIAL_IDS

    effort = {t: 1.0 + 0.5 * t.endswith("H") for t in TRIAL_IDS}
    effort["6H"] = 1.0 + 0.5 * TIE_REL  # inside the rule
    effort["9H"] = 1.0 + 2.0 * TIE_REL  # outside it
    e = pd.DataFrame({"trial": list(effort), "effort": list(effort.values())})
    r = pd.DataFrame({"trial": list(TRIAL_IDS), "sigma": 0.065, "risk": 0.1})
    t = pair_orderings(e, r, 0.065, {p: "d" for p in range(1, 13)}).set_index("pair")
    assert t.loc[6, "eq1_tie"] and t.loc[6, "effort_order"] == "tie"
    assert not t.loc[9, "eq1_tie"] and t.loc[9, "effort_order"] == "E<H" and t.loc[9, "eq1_ratio_low"] < 0


def test_histogram_draws_every_layout_once():
    from lgp.app.charts import histogram_svg

    values = np.random.default_rng(0).normal(0.5, 0.05, 30)
    svg = histogram_svg(values)
    counts = [int(c) for c in re.findall(r"<title>(\d+) layouts in", svg)]
    assert sum(counts) == 30 and len(counts) == 10
    assert sum(int(c) for c in re.findall(r"<title>(\d+) layouts", histogram_svg(np.full(5, 0.3)))) == 5


def test_a_page_without_a_trials_rows_names_the_trial(tmp_path):
    from lgp.app.page import write_page

    trial = stimuli.load_trial("1E")
    samples = pd.DataFrame({"trial": ["1E"], "sample": [0], "effort": [0.1], "n_actions": [4]})
    with pytest.raises(ValueError, match="1E"):
        write_page(tmp_path, run={}, trials=[trial], effort_samples=samples,
                   risk=pd.DataFrame(columns=["trial", "sigma", "risk"]), sigma=0.065)


def test_the_page_shows_fits_profile_bootstrap_and_every_participant(tmp_path):
    """With (here SIMULATED) responses the page carries the Results section, labelled."""
    from analysis.run import run_analysis
    from analysis.simulate import simulate_participants
    from lgp.app.page import write_page
    from lgp.paper import TRIAL_IDS

    trials = stimuli.load_all()
    rng = np.random.default_rng(1)
    effort = pd.DataFrame([{"trial": t, "sample": s, "effort": 0.2 + 0.05 * k + 0.01 * s, "n_actions": 8}
                           for k, t in enumerate(TRIAL_IDS) for s in range(2)])
    risk = pd.DataFrame([{"trial": t, "sigma": sg, "risk": float(rng.uniform(0, sg * 3))}
                         for t in TRIAL_IDS for sg in (0.05, 0.065, 0.08)])
    people = simulate_participants(effort, risk, (0.0, 1.0, 4.0), 0.065, {"difficulty": 7, "time": 5}, 0.1,
                                   np.random.default_rng(0), datasets=["difficulty", "time"])
    analysis = run_analysis(people, effort, risk, tmp_path / "analysis", seed=0, n_boot=20, jobs=1, figures=False)
    page = write_page(tmp_path, run={}, trials=trials, effort_samples=effort, risk=risk, sigma=0.065,
                      analysis=analysis).read_text()
    human = page[page.index('<section id="human">'):]
    assert "SIMULATED participants, not human data" in human
    for title in ("Fits of Eq. 1", "RMSE profile over sigma", "Bootstrap over participants", "Direct bootstrap tests", "Participants"):
        assert title in human
    participants = human[human.index("<h3>Participants</h3>"):human.index("</section>")]  # not the comparison after it
    assert participants.count("<tr>") - 1 == 12  # one row per participant, plus the header


@pytest.mark.slow  # a fresh interpreter
def test_drawing_a_figure_leaves_the_callers_matplotlib_backend_alone(tmp_path):
    """Issue 21: the figure writers called matplotlib.use("Agg"), which switched a
    notebook's backend off; they draw on their own Figure now."""
    import matplotlib

    from lgp.app.pictures import trial_picture
    from lgp.app.sensitivity import risk_sensitivity_figure
    from stimuli.sheet import contact_sheet

    before = matplotlib.get_backend()
    matplotlib.use("svg")  # not Agg, as a notebook's inline backend is not
    try:
        trial = stimuli.load_trial("1E")
        trial_picture(trial, 0, tmp_path / "1E.png")
        contact_sheet([trial], out=str(tmp_path / "sheet.png"))
        table = pd.DataFrame({"engine": "mujoco", "faithful": True, "fall_rule": "horizontal", "fall_threshold": 0.25,
                              "trial": ["4E", "4E", "4H", "4H"], "sigma": [0.065, 0.1] * 2, "risk": [0.0, 0.1, 0.0, 0.2]})
        risk_sensitivity_figure(table, tmp_path / "figures" / "risk.png")
        assert matplotlib.get_backend() == "svg"
    finally:
        matplotlib.use(before)
    for name in ("1E.png", "sheet.png", "figures/risk.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

"""Numbers as the results page writes them (lgp.app.page, lgp.app.charts): at most 4
significant digits, round-off of a fixed layout not printed as a spread, no raw nan,
a bootstrap p of 0 as "< 1/n", every risk plot on one axis 0..1 with its Wilson band,
and a chosen sigma at the edge of its grid warned about."""
import re

import numpy as np
import pandas as pd
import pytest

from lgp.app.charts import num, risk_svg
from lgp.app.page import p_value, percent, plus_minus
from lgp.app.report import sigma_edge_warnings


@pytest.mark.parametrize("value, text", [(0.115912345, "0.1159"), (2124.0, "2124"), (20000.0, "20000"),
                                         (1.5e-5, "1.5e-05"), (float("nan"), "n/a"), (None, "n/a"), (0.065, "0.065")])
def test_a_number_has_at_most_four_significant_digits(value, text):
    assert num(value) == text


def test_a_spread_of_round_off_is_not_printed_as_a_spread():
    # 10E's case: every layout gives the same plan, sd 4.2e-17 on 0.1159 J s
    assert plus_minus(0.11591, 4.2e-17, "J s", 30) == "0.1159 J s <small>(same for every layout)</small>"
    # a real spread: the mean rounded to the sd's last digit, the sd to 2 digits
    assert plus_minus(0.37123, 0.07432, "J s", 3) == "0.371 &plusmn; 0.074 J s"


def test_a_bootstrap_p_of_zero_is_a_bound_and_nan_is_not_shown():
    assert p_value(0.0, 200) == "< 1/200"
    assert p_value(0.0312, 200) == "0.031"
    assert p_value(float("nan"), 200) == "n/a"


def test_relative_differences_are_percent_and_a_tie_says_so():
    assert percent(1.2612) == "+126 %"
    assert percent(1.01e-5) == "+0.001 % (tie)"
    assert percent(1.1e-16) == "0 %"


def test_every_risk_plot_shares_one_axis_from_0_to_1_with_its_wilson_band():
    """One fall in 20 (0.05) stays near the floor of a 0..1 axis instead of filling a
    plot scaled to its own curve; the band spans each point's interval."""
    from models.risk.core import wilson_interval

    lo, hi = zip(*(wilson_interval(k, 20) for k in (0, 1, 0)))
    svg = risk_svg([0.05, 0.065, 0.08], [0.0, 0.05, 0.0], 0.065, lo, hi)
    assert 'data-ymin="0" data-ymax="1"' in svg and ">1</text>" in svg and ">0</text>" in svg
    frame = re.search(r'class="frame" x="[\d.]+" y="([\d.]+)" width="[\d.]+" height="([\d.]+)"', svg)
    top, height = float(frame.group(1)), float(frame.group(2))
    ys = [float(p.split(",")[1]) for p in svg.split('points="')[-1].split('"')[0].split()]
    # the 0.05 point sits 5 % of the frame above the floor
    assert ys[1] == pytest.approx(top + height * 0.95, abs=0.1) and ys[0] == pytest.approx(top + height, abs=0.1)
    band = [tuple(map(float, p.split(","))) for p in re.search(r'class="band" points="([^"]+)"', svg).group(1).split()]
    # upper edge at the three upper bounds, then the lower edge back
    assert [y for _, y in band[:3]] == pytest.approx([top + height * (1 - h) for h in hi], abs=0.1)
    assert [y for _, y in band[3:]] == pytest.approx([top + height * (1 - v) for v in lo[::-1]], abs=0.1)


def test_a_sigma_chosen_at_the_edge_of_the_grid_is_warned_about():
    profile = pd.DataFrame({"dataset": ["a"] * 3, "sigma": [0.05, 0.065, 0.1], "rmse": [0.3, 0.2, 0.1]})
    edge = {"sigma_profile": profile, "sigma_choice": pd.DataFrame({"dataset": ["a"], "sigma": [0.1]})}
    inside = {"sigma_profile": profile, "sigma_choice": pd.DataFrame({"dataset": ["a"], "sigma": [0.065]})}
    (warning,) = sigma_edge_warnings(edge)
    assert "upper edge of the grid (0.05 to 0.1 d)" in warning and "--sigmas" in warning
    assert sigma_edge_warnings(inside) == [] and sigma_edge_warnings(None) == []


def test_a_run_without_a_whole_pair_says_why_it_has_no_pair_table():
    """A designed set without pairs (or a subset of the paper's trials) has no pair
    table; the page says that, not that all 24 trials are needed."""
    from lgp.app import page

    html = page._pairs_section(None, None)
    assert "No pair table: no two trials of this run are the easy and hard trial of one pair" in html
    assert "needs all 24" not in html

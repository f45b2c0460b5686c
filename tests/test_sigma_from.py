"""`lgp.reproduce --sigma-from FILE`: a sigma measured on another lab's data
(analysis.mental_jenga's summary.json) joins the run's grid and its report."""
import json

import pytest

from lgp.app.sigma_from import grid_with, read_sigma_from, report_lines
from lgp.errors import InputError
from lgp.paper import SIGMA_GRID


def summary(tmp_path, sigma=0.12, interval=(0.09, 0.18)):
    p = tmp_path / "summary.json"
    p.write_text(json.dumps({"experiment": 2, "rules": {"paper-3d": {"best_sigma": sigma, "best_sigma_interval_95": list(interval),
                                                                     "held_out_r": 0.7}}}))
    return p


def test_the_linked_sigma_joins_the_grid_once_and_in_order(tmp_path):
    link = read_sigma_from(summary(tmp_path))
    grid = grid_with(SIGMA_GRID, link)
    assert 0.12 in grid and list(grid) == sorted(grid) and len(grid) == len(SIGMA_GRID) + 1
    assert grid_with(SIGMA_GRID, read_sigma_from(summary(tmp_path, 0.065))) == SIGMA_GRID  # already there
    assert grid_with(SIGMA_GRID, read_sigma_from(summary(tmp_path, 0.0))) == SIGMA_GRID  # no noise: no grid point


def test_the_report_says_whether_the_papers_sigma_lies_in_the_interval(tmp_path):
    text = "\n".join(report_lines(read_sigma_from(summary(tmp_path)), 0.065, None, "| pair |"))
    assert "best sigma 0.12 d" in text and "0.065 d outside the interval" in text and "| pair |" in text
    text = "\n".join(report_lines(read_sigma_from(summary(tmp_path, 0.07, (0.05, 0.1))), 0.065, 0.08, None))
    assert "0.065 d inside" in text and "fitted to the difficulty ratings is 0.08 d" in text


@pytest.mark.parametrize("content, problem", [("{", "not valid JSON"), ('{"rules": {}}', "with a 'paper-3d' sigma"),
                                               ('{"rules": {"paper-3d": {"best_sigma": 7, "best_sigma_interval_95": [0, 1]}}}',
                                                r"not in \[0, 1\]")])
def test_a_bad_summary_is_refused_naming_the_file(tmp_path, content, problem):
    p = tmp_path / "s.json"
    p.write_text(content)
    with pytest.raises(InputError, match=problem) as e:
        read_sigma_from(p)
    assert str(p) in str(e.value)


def test_reproduce_refuses_a_bad_summary_before_any_work(tmp_path, capsys):
    from lgp.reproduce import parse_args

    p = tmp_path / "s.json"
    p.write_text("{}")
    with pytest.raises(SystemExit) as e:
        parse_args(["--sigma-from", str(p), "--out", str(tmp_path / "out")])
    assert e.value.code == 2 and "s.json" in capsys.readouterr().err
    config = parse_args(["--sigma-from", str(summary(tmp_path)), "--out", str(tmp_path / "out")])
    assert 0.12 in config.sigmas and not (tmp_path / "out").exists()

"""`python -m analysis.mental_jenga` end to end on a tiny clone written by hand (two
scenes of tests/data/mental_jenga, two SIMULATED participants made up here for the
test, not data), and `lgp.reproduce --sigma-from` reading the summary.json it wrote."""
import json

import numpy as np
import pandas as pd
import pytest

from tests.test_mental_jenga import fake_repo


@pytest.mark.slow
def test_the_command_fits_a_tiny_clone_and_reproduce_takes_its_sigma(tmp_path, capsys):
    from analysis.mental_jenga import main
    from lgp.app.sigma_from import read_sigma_from
    from lgp.reproduce import parse_args

    pred = pd.DataFrame({"participant": [1, 1, 2, 2], "condition": "prediction", "order": 1,
                         "trial": [1.0, 2.0, 1.0, 2.0], "response": [1.0, 2.0, 2.0, 1.0]})  # SIMULATED
    repo = fake_repo(tmp_path, {1: "stacked", 2: "overhang"}, pred)
    out = tmp_path / "fit"
    argv = ["--repo", str(repo), "--experiment", "2", "--out", str(out), "--runs", "2", "--sigmas", "0.05,0.2", "--jobs", "1",
            "--engine", "mujoco"]  # the paper's rule, which --sigma-from reads, needs a 3-D engine
    assert main(argv) == 0
    printed = capsys.readouterr().out.splitlines()
    summary = json.loads((out / "summary.json").read_text())
    fit, means = pd.read_csv(out / "fit.csv"), pd.read_csv(out / "scenes.csv")
    assert summary["human_means"] == {"1": 1.5, "2": 1.5} and summary["scenes_used"] == 2
    # fit.csv against r and RMSE recomputed by hand from the per-scene means it was made from
    for row in fit.itertuples():
        m = means[(means.rule == row.rule) & np.isclose(means.sigma, row.sigma)].sort_values("scene")["mean"].to_numpy()
        assert row.rmse == pytest.approx(np.sqrt(np.mean((m - 1.5) ** 2)))
    assert len(fit) == 4 and set(fit.sigma) == {0.05, 0.2}
    for rule, line in zip(("authors-x", "paper-3d"), printed):
        best = fit[fit.rule == rule].sort_values(["rmse", "sigma"]).iloc[0]
        assert summary["rules"][rule]["best_sigma"] == best.sigma
        assert line.startswith(f"{rule}: best sigma {best.sigma:g} ") and f"RMSE {best.rmse:.3f}" in line
    # lgp.reproduce --sigma-from takes the paper's rule's best sigma into its grid, before any work
    link = read_sigma_from(out / "summary.json")
    assert link.sigma == summary["rules"]["paper-3d"]["best_sigma"] and link.experiment == 2
    config = parse_args(["--sigma-from", str(out / "summary.json"), "--out", str(tmp_path / "run")])
    assert link.sigma in config.sigmas and not (tmp_path / "run").exists()


def test_a_folder_holding_a_users_file_is_refused_before_any_simulation_and_left_as_it_was(tmp_path, capsys):
    from analysis.mental_jenga import main

    repo = fake_repo(tmp_path, {1: "stacked"})
    user = tmp_path / "mine"
    user.mkdir()
    (user / "fit.csv").write_text("my own fit\n")
    assert main(["--repo", str(repo), "--experiment", "2", "--out", str(user), "--runs", "1", "--sigmas", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no run of this command wrote (fit.csv) and no summary.json" in err[0], err
    assert [p.name for p in user.iterdir()] == ["fit.csv"] and (user / "fit.csv").read_text() == "my own fit\n"

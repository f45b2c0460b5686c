"""lgp.reproduce --human-data on a trial set other than the paper's 24 (issue 34):
the human data name the run's own trials, the fits are made on them, and what
needs easy/hard pairs is left out with its reason instead of crashing."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.data import HumanDataError, using_trials, validate_human_data


def _responses(trials, participants=3):
    rng = np.random.default_rng(1)
    return pd.DataFrame([("simulated-time", f"p{k}", t, float(rng.normal())) for k in range(participants)
                         for t in trials], columns=["dataset", "participant", "trial", "response"])


def test_the_data_must_name_exactly_the_runs_trials_and_a_stray_or_missing_one_is_named():
    trials = ["G0001", "G0002", "G0003", "G0004", "G0005"]
    with using_trials(trials):
        ok = validate_human_data(_responses(trials), allow_simulated=True)
        assert sorted(ok["trial"].unique()) == trials
        stray = _responses(trials).replace({"trial": {"G0005": "1E"}})
        with pytest.raises(HumanDataError, match=r"unknown trial id '1E'; expected one of the run's trials G0001, .*G0005"):
            validate_human_data(stray, allow_simulated=True)
        short = _responses(trials[:4])
        with pytest.raises(HumanDataError, match="is missing trial\\(s\\) G0005"):
            validate_human_data(short, allow_simulated=True)
    # outside the block the paper's 24 are the set again: the same file names unknown trials
    with pytest.raises(HumanDataError, match="unknown trial id 'G0001'; expected one of the run's trials 1E, 1H, ..., 12H"):
        validate_human_data(_responses(trials), allow_simulated=True)


@pytest.mark.slow
def test_reproduce_fits_a_generated_set_with_simulated_participants_and_says_why_pair_tables_are_absent(tmp_path, capsys):
    from analysis.simulate import simulate_participants
    from lgp import reproduce
    from stimuli.generate import generate

    stim = tmp_path / "stim"
    generate(stim, 6, seed=2)
    out = tmp_path / "r"
    small = ["--quick", "--stimuli", str(stim), "--samples", "1", "--n-sims", "8", "--sigmas", "0.065", "0.1",
             "--jobs", "1", "--n-boot", "20", "--n-perm", "9", "--no-replays", "--out", str(out)]
    assert reproduce.main(small) == 0                       # effort and risk of the generated trials
    effort, risk = pd.read_csv(out / "effort.csv"), pd.read_csv(out / "risk.csv")
    ids = sorted(effort["trial"].unique())
    assert len(ids) == 6
    with using_trials(ids):  # SIMULATED participants drawn from Eq. 1 on these trials' own effort and risk
        E = effort.set_index("trial")["effort"]
        sim = simulate_participants(E, risk, (0.0, 1.0, 2.0), 0.065, 10, 0.5, np.random.default_rng(4),
                                    datasets=("time",))
    assert set(sim["dataset"]) == {"simulated-time"}
    data = tmp_path / "sim.csv"
    sim.to_csv(data, index=False)
    capsys.readouterr()
    assert reproduce.main(small + ["--human-data", str(data), "--allow-simulated"]) == 0
    err = capsys.readouterr().err
    fits = pd.read_csv(out / "analysis" / "simulated_fits.csv")
    assert set(fits["model"]) >= {"full", "effort", "risk"} and (fits["n_trials"] == 6).all()
    assert not (out / "analysis" / "simulated_orderings.csv").exists()
    skipped = pd.read_csv(out / "analysis" / "simulated_skipped.csv")
    assert "orderings (pair tables)" in set(skipped["what"])
    assert skipped["reason"].str.contains("no easy/hard pair").all() or "leave-one-pair-out" in " ".join(skipped["what"])
    perm = pd.read_csv(out / "analysis" / "simulated_permutation_test.csv").set_index("kind")
    assert perm.loc["within-pair", "calibration"].startswith("skipped: no easy/hard pairs")
    assert perm.loc["freedman-lane", "n_perm"] == 9
    assert "orderings (pair tables) left out: the 6 trials hold no easy/hard pair" in err
    report = (out / "report.md").read_text()
    assert "## Left out for this trial set (skipped.csv)" in report and "## fits (in-sample)" in report


def test_human_data_on_fewer_than_five_trials_is_refused_in_one_line_before_any_work(tmp_path, capsys):
    from lgp import reproduce

    data = tmp_path / "h.csv"
    _responses(["1E", "1H", "2E"]).to_csv(data, index=False)
    out = tmp_path / "r"
    from lgp import cli

    assert cli.run_cli(reproduce.main, ["--trials", "1E", "1H", "2E", "--human-data", str(data), "--allow-simulated",
                                        "--out", str(out)], prog=reproduce.PROG) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "need at least 5 trials; this run has 3 (1E, 1H, 2E)" in err[0], err
    assert not out.exists()

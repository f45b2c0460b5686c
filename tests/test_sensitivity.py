"""The risk sensitivity section of `python -m lgp.reproduce --sensitivity`: one
tidy row per engine, fall rule, trial and sigma, each equal to the risk the risk
API gives for that engine and rule; the summary counts what the table holds; a
second run simulates nothing."""

import numpy as np
import pandas as pd
import pytest

import stimuli
from lgp import reproduce
from lgp.app import sensitivity
from lgp.app import stages
from lgp.app.cache import Cache
from lgp.app.config import RunConfig
from lgp.executor import SerialExecutor
from models.risk import RiskModel, available_engines, risk_table

ENGINES = [e for e in ("mujoco", "physx", "physx:game-defaults") if e in available_engines()]


def context(tmp_path, trials):
    args = RunConfig(n_sims=6, seed=2, sensitivity_engines=tuple(ENGINES))
    return sensitivity.Context(args, trials, SerialExecutor(), Cache(tmp_path / "cache"), tmp_path,
                               stages.risk_key_inputs, lambda m: None)


@pytest.mark.slow
def test_risk_section_is_tidy_matches_the_api_and_is_cached(tmp_path, monkeypatch):
    trials = [stimuli.load_trial(t) for t in ("4E", "4H")]
    ctx = context(tmp_path, trials)
    section = sensitivity.risk_section(ctx)
    assert not (tmp_path / "risk_sensitivity.csv").exists()  # a section computes; the writer writes
    written = sensitivity.write_sections([section], tmp_path)
    assert [p.relative_to(tmp_path).as_posix() for p in written] == [
        "risk_sensitivity.csv", "risk_sensitivity_summary.csv", "figures/risk_sensitivity.png"]
    table = pd.read_csv(tmp_path / "risk_sensitivity.csv")
    assert list(table.columns) == sensitivity.COLUMNS
    assert len(table) == (len(ENGINES) * len(sensitivity.RISK_RULES) * len(sensitivity.NOISE_RULES) * len(trials)
                          * len(sensitivity.RISK_SIGMAS))
    assert not table.duplicated(["engine", "fall_rule", "fall_threshold", "noise_rule", "trial", "sigma"]).any()
    assert set(table["noise_rule"]) == {"lift", "settle"}
    assert table.loc[table["engine"] == "physx:game-defaults", "faithful"].eq(False).all()

    # every cell is what the risk API gives with that engine and rule, simulated directly
    for (engine, rule, thr, noise_rule), g in table.groupby(["engine", "fall_rule", "fall_threshold", "noise_rule"]):
        model = RiskModel(engine, None, rule, thr, noise_rule)
        direct = risk_table(trials, list(sensitivity.RISK_SIGMAS), n_sims=6, seed=2, model=model, jobs=1)
        merged = g.merge(direct, on=["trial", "sigma"], suffixes=("", "_api"))
        assert len(merged) == len(g)
        np.testing.assert_array_equal(merged["risk"], merged["risk_api"])

    summary = pd.read_csv(tmp_path / "risk_sensitivity_summary.csv")
    for _, row in summary.iterrows():
        g = table[(table["engine"] == row["engine"]) & (table["fall_rule"] == row["fall_rule"])
                  & (table["noise_rule"] == row["noise_rule"])
                  & (table["fall_threshold"] == row["fall_threshold"]) & np.isclose(table["sigma"], row["sigma"])]
        assert row["trials_risk_gt_0"] == (g["risk"] > 0).sum()
        risk = dict(zip(g["trial"], g["risk"]))
        assert row["4H>4E"] == (risk["4H"] > risk["4E"])
    assert (tmp_path / "figures" / "risk_sensitivity.png").stat().st_size > 10_000
    assert section.lines[0].startswith("## Sensitivity of risk") and any("UNFAITHFUL" in l for l in section.lines) == (
        "physx:game-defaults" in ENGINES)

    # cached: a second section simulates nothing and writes the same table
    monkeypatch.setattr("models.risk.risk_table", lambda *a, **k: pytest.fail("simulated again"))
    sensitivity.write_sections([sensitivity.risk_section(ctx)], tmp_path)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "risk_sensitivity.csv"), table)


def test_sections_are_a_list_a_new_one_can_join(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(sensitivity, "SECTIONS", [lambda ctx: calls.append(ctx) or sensitivity.Section("x", ["## x"])])
    ctx = context(tmp_path, [])
    assert [s.lines for s in sensitivity.run_sections(ctx)] == [["## x"]] and calls == [ctx]


def test_unknown_sensitivity_engine_is_one_error_line(capsys):
    with pytest.raises(SystemExit) as e:
        reproduce.main(["--sensitivity", "--sensitivity-engines", "bullet", "--out", "/nonexistent/x"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("python -m lgp.reproduce: error: unknown physics engine 'bullet'")


@pytest.mark.parametrize("args,message", [(["--fall-threshold", "-1"], "fall threshold must be > 0"),
                                          (["--fall-rule", "up"], "unknown fall rule"),
                                          (["--engine", "physx", "--profile", "x"], "unknown physx profile")])
def test_bad_risk_options_of_reproduce_are_one_error_line(capsys, args, message):
    with pytest.raises(SystemExit) as e:
        reproduce.main([*args, "--out", "/nonexistent/x"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_fall_rule_is_part_of_the_risk_cache_key():
    keys = {str(sorted(stages.risk_key_inputs(judge).items())) for judge in sensitivity.RISK_RULES}
    assert len(keys) == len(sensitivity.RISK_RULES)


def test_the_help_of_sensitivity_says_it_also_runs_the_slow_effort_section():
    """Issue 21: the help said "risk by engine and fall rule" only, but the flag also
    plans every trial under three more motion designs (the effort section)."""
    import argparse

    parser = argparse.ArgumentParser()
    sensitivity.add_arguments(parser)
    text = next(a.help for a in parser._actions if "--sensitivity" in a.option_strings)
    assert "risk by engine and fall rule" in text and "effort by motion design" in text and "slow" in text
    assert [s.__name__ for s in sensitivity.SECTIONS] == ["risk_section", "effort_section"]  # what the help names

"""`python -m lgp.reproduce` runs the pipeline, caches what it computed, and a run
interrupted half way resumes to the same numbers as an uninterrupted one."""
import pandas as pd
import pytest

import models.effort
import models.risk
from lgp import reproduce

ARGS = ["--trials", "9E", "10E", "6H", "--samples", "1", "--n-sims", "4", "--sigmas", "0.05", "0.1", "--jobs", "1", "--seed", "3"]


def _tables(out):
    """The result tables, less wall-clock columns (they differ run to run)."""
    tables = {name: pd.read_csv(out / f"{name}.csv") for name in ("effort_samples", "effort", "risk")}
    return {name: df.drop(columns=[c for c in df if c.endswith("_time")]) for name, df in tables.items()}


def test_reproduce_writes_tables_and_report_then_reuses_the_cache(tmp_path, monkeypatch):
    out = tmp_path / "r"
    assert reproduce.main([*ARGS, "--out", str(out)]) == 0
    first = _tables(out)
    assert set(first["risk"]["trial"]) == {"9E", "10E", "6H"} and len(first["risk"]) == 6
    assert (first["effort"]["effort"] > 0).all()
    assert "Physical effort" in (out / "report.md").read_text()

    # A second run must not simulate or plan anything: make both fail if called.
    def boom(*a, **k):
        raise AssertionError("recomputed a cached result")

    monkeypatch.setattr(models.risk, "risk_table", boom)
    monkeypatch.setattr(models.effort, "physical_effort", boom)
    assert reproduce.main([*ARGS, "--out", str(out)]) == 0
    for name, df in _tables(out).items():
        pd.testing.assert_frame_equal(df, first[name])


def test_interrupted_run_resumes_to_the_same_results(tmp_path, monkeypatch):
    whole = tmp_path / "whole"
    reproduce.main([*ARGS, "--out", str(whole)])

    cut = tmp_path / "cut"
    real = models.risk.risk_table
    calls = []

    def dies_on_second_chunk(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(models.risk, "risk_table", dies_on_second_chunk)
    assert reproduce.main([*ARGS, "--out", str(cut), "--risk-chunk", "2"]) == 130  # Ctrl-C: one line, exit 128 + 2
    monkeypatch.setattr(models.risk, "risk_table", real)
    assert len(list((cut / "cache").glob("risk-*.csv"))) == 2  # the first chunk survived whole
    reproduce.main([*ARGS, "--out", str(cut), "--risk-chunk", "2"])
    for name, df in _tables(cut).items():
        pd.testing.assert_frame_equal(df, _tables(whole)[name])


def test_kappa_range_matches_brute_force_over_ratios():
    import numpy as np

    rng = np.random.default_rng(0)
    kappas = np.linspace(0, 50, 50001)
    for _ in range(200):
        E_e, E_h = rng.uniform(0.05, 1, 2)
        R_e, R_h = rng.choice([0.0, 0.01, 0.2, 0.5], 2)
        text = reproduce.kappa_range(E_e, R_e, E_h, R_h)
        ok = E_h * (1 - R_h) + kappas * E_h * R_h > E_e * (1 - R_e) + kappas * E_e * R_e
        if text == "any":
            assert ok.all()
        elif text == "none":
            assert not ok.any()
        else:
            bound = float(text[2:])
            expect = kappas > bound if text[0] == ">" else kappas < bound
            far = np.abs(kappas - bound) > 1e-2 * max(1, bound)  # away from the 3-digit rounding
            assert (ok[far] == expect[far]).all()


def test_no_cache_simulates_each_trial_once(tmp_path, monkeypatch):
    real, calls = models.risk.risk_table, []

    def counted(trials, *a, **k):
        calls.append([t.id for t in trials])
        return real(trials, *a, **k)

    monkeypatch.setattr(models.risk, "risk_table", counted)
    reproduce.main([*ARGS, "--out", str(tmp_path / "r"), "--no-cache"])
    assert sorted(sum(calls, [])) == ["10E", "6H", "9E"]


def _fake_physics(monkeypatch):
    """Effort and risk tables without planning or simulating: this checks which
    trials reach which stage, not model numbers (those have their own tests)."""
    def effort(trials, samples, seed, executor, cache):
        return pd.DataFrame([{"trial": t.id, "sample": s, "effort": 1.0 + t.pair / 10 + (t.level == "H") + s / 100}
                             for t in trials for s in range(samples)])

    def risk(trials, sigmas, n_sims, seed, engine, executor, cache, chunk=6):
        return pd.DataFrame([{"trial": t.id, "sigma": s, "risk": min(1.0, s * (2 if t.level == "H" else 1)),
                              "falls": 0, "n": n_sims, "engine": "none"} for t in trials for s in sigmas])

    monkeypatch.setattr(reproduce, "effort_tables", effort)
    monkeypatch.setattr(reproduce, "risk_tables", risk)


def test_an_extra_trial_file_does_not_break_the_paper_run(tmp_path, monkeypatch, capsys):
    """A valid 13E.yaml beside the paper's 24 (as stimuli/README.md invites): the
    default run is the paper's 24 and names 13E; `--trials all` runs 13E too, in
    the effort and risk tables, while pairs and figures stay on the paper's 24."""
    import yaml

    import stimuli

    folder = tmp_path / "trials"
    folder.mkdir()
    for path in stimuli.TRIAL_DIR.glob("*.yaml"):
        (folder / path.name).write_text(path.read_text())
    data = yaml.safe_load((folder / "7H.yaml").read_text())
    data.update(id="13E", pair=13, level="E")
    (folder / "13E.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.setattr(stimuli, "TRIAL_DIR", folder)
    _fake_physics(monkeypatch)
    args = ["--samples", "2", "--n-sims", "4", "--sigmas", "0.05", "0.065", "--jobs", "1", "--n-boot", "10"]

    assert reproduce.main([*args, "--out", str(tmp_path / "paper")]) == 0
    assert "also holds 13E" in capsys.readouterr().err
    effort = pd.read_csv(tmp_path / "paper" / "effort.csv")
    assert list(effort["trial"]) == [f"{p}{l}" for p in range(1, 13) for l in "EH"]

    assert reproduce.main([*args, "--trials", "all", "--out", str(tmp_path / "all")]) == 0
    assert list(pd.read_csv(tmp_path / "all" / "effort.csv")["trial"])[-1] == "13E"
    assert "13E" in set(pd.read_csv(tmp_path / "all" / "risk.csv")["trial"])
    assert sorted(pd.read_csv(tmp_path / "all" / "pairs.csv")["pair"]) == list(range(1, 13))
    assert "13E are in the effort and risk tables only" in capsys.readouterr().err

"""`python -m lgp.reproduce` runs the pipeline, caches what it computed, and a run
interrupted half way, or one whose cache was damaged, ends with the same numbers as
an undisturbed one."""
import dataclasses
import re
import shutil

import pandas as pd
import pytest

from lgp.app.cache import read_entry

import models.effort
import models.risk
from lgp import reproduce
from lgp.app import run as app_run

ARGS = ["--trials", "9E", "10E", "6H", "--samples", "1", "--n-sims", "4", "--sigmas", "0.05", "0.1", "--jobs", "1", "--seed", "3",
        "--verbose"]  # --verbose: the per-trial lines these tests read


def _run(args):
    """The run of the command line `args` (written into its --out), its lgp.app.result.RunResult."""
    return reproduce.reproduce(reproduce.parse_args(args), args)


def _cache_counts(result, kinds=("effort", "riskruns")) -> dict:
    """The run's cache lookups {(kind, outcome): n} (its RunRecord) for entries of
    `kinds` that were looked up (default: the result tables, not the B-stands checks)."""
    counts = result.record.cache_counts
    looked = {kind for kind, _ in counts}
    return {(kind, o): counts.get((kind, o), 0) for kind in kinds if kind in looked for o in ("hit", "miss", "recomputed")}


def _tables(out):
    """The result tables, less wall-clock columns (they differ run to run)."""
    tables = {name: pd.read_csv(out / f"{name}.csv") for name in ("effort_samples", "effort", "risk")}
    return {name: df.drop(columns=[c for c in df if c.endswith("_time")]) for name, df in tables.items()}


@pytest.mark.slow
def test_reproduce_writes_tables_and_report_then_reuses_the_cache(undisturbed, tmp_path, capsys):
    whole, _, result = undisturbed  # the first run of ARGS into a fresh folder
    out = tmp_path / "r"
    shutil.copytree(whole, out)
    assert _cache_counts(result) == {("effort", "hit"): 0, ("effort", "miss"): 3, ("effort", "recomputed"): 0,
                                     ("riskruns", "hit"): 0, ("riskruns", "miss"): 3, ("riskruns", "recomputed"): 0}
    assert _cache_counts(result, ["stable"])["stable", "miss"] == 3  # B checked once per trial, before effort
    first = _tables(out)
    assert set(first["risk"]["trial"]) == {"9E", "10E", "6H"} and len(first["risk"]) == 6
    assert (first["effort"]["effort"] > 0).all()
    report = (out / "report.md").read_text()
    assert "Physical effort" in report
    from importlib.metadata import version

    assert f"mujoco {version('mujoco')}" in report and '"timestep": 0.002' in report  # libraries and engine settings

    # A second run plans and simulates nothing: every lookup is a hit.
    result = _run([*ARGS, "--out", str(out)])
    assert _cache_counts(result) == {("effort", "hit"): 3, ("effort", "miss"): 0, ("effort", "recomputed"): 0,
                                     ("riskruns", "hit"): 3, ("riskruns", "miss"): 0, ("riskruns", "recomputed"): 0}
    assert _cache_counts(result, ["stable"])["stable", "hit"] == 3
    for name, df in _tables(out).items():
        pd.testing.assert_frame_equal(df, first[name])


@pytest.mark.slow
def test_interrupted_run_resumes_to_the_same_results(undisturbed, tmp_path, monkeypatch, capsys):
    whole, _, _ = undisturbed  # the same command line, run once without interruption (read only)
    cut = tmp_path / "cut"
    real = models.risk.risk_table
    calls = []

    def dies_on_second_chunk(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(models.risk, "risk_table", dies_on_second_chunk)
    capsys.readouterr()
    assert reproduce.main([*ARGS, "--out", str(cut), "--risk-chunk", "2"]) == 130  # stopped as Ctrl-C stops it
    assert "interrupted" in capsys.readouterr().err
    monkeypatch.setattr(models.risk, "risk_table", real)
    assert len(list((cut / "cache").glob("riskruns-*.csv"))) == 2  # the first chunk survived whole
    counts = _cache_counts(_run([*ARGS, "--out", str(cut), "--risk-chunk", "2"]))
    assert (counts["effort", "hit"], counts["riskruns", "hit"], counts["riskruns", "miss"]) == (3, 2, 1)
    for name, df in _tables(cut).items():
        pd.testing.assert_frame_equal(df, _tables(whole)[name])


def test_the_ratio_range_of_eq1_matches_brute_force_over_ratios():
    """analysis.pairs.ratio_range (numbers) against Eq. 1 evaluated on a fine grid of
    b2/b1, and its words in pairs.csv (lgp.app.report.ratio_text) against the same."""
    import math

    import numpy as np

    from analysis.pairs import ratio_range
    from lgp.app.report import ratio_text

    rng = np.random.default_rng(0)
    kappas = np.linspace(0, 50, 50001)
    for _ in range(200):
        E_e, E_h = rng.uniform(0.05, 1, 2)
        R_e, R_h = rng.choice([0.0, 0.01, 0.2, 0.5], 2)
        r = ratio_range(E_e, R_e, E_h, R_h)
        ok = E_h * (1 - R_h) + kappas * E_h * R_h > E_e * (1 - R_e) + kappas * E_e * R_e
        assert (ok == ((kappas > r.low) & (kappas < r.high))).all()
        assert (not r.every or ok.all()) and (not r.empty or not ok.any())
        text = ratio_text(r)
        if r.every:
            assert text == "any"
        elif r.empty:
            assert text == "none"
        else:
            bound = r.low if r.high == math.inf else r.high
            assert text == f"{'>' if r.high == math.inf else '<'} {bound:.3g}"
    assert ratio_text(ratio_range(1.0, 0.0, 1.0, 0.0, tie=True)) == "none (tie)"


@pytest.mark.slow
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
    def effort(trials, samples, seed, executor, cache, **design):
        return pd.DataFrame([{"trial": t.id, "sample": s, "effort": 1.0 + t.pair / 10 + (t.level == "H") + s / 100}
                             for t in trials for s in range(samples)])

    def risk(trials, sigmas, n_sims, seed, engine, executor, cache, chunk=6, runs_out=None, **fall_rule):
        table = pd.DataFrame([{"trial": t.id, "sigma": s, "risk": min(1.0, s * (2 if t.level == "H" else 1)),
                               "falls": 0, "n": n_sims, "engine": "none"} for t in trials for s in sigmas])
        table = table.assign(risk_low=table["risk"], risk_high=table["risk"])  # no Monte Carlo error: a stand-in
        if runs_out is not None:  # the runs' verdicts, as the real stage hands them on (for risk_precision.csv)
            runs_out.append(pd.DataFrame([{"trial": r.trial, "sigma": r.sigma, "run": k, "fell": k < r.risk * n_sims}
                                          for r in table.itertuples() for k in range(n_sims)]))
        return table

    monkeypatch.setattr(app_run, "effort_tables", effort)
    monkeypatch.setattr(app_run, "risk_tables", risk)
    monkeypatch.setattr(app_run, "write_replays", lambda *a, **k: None)  # nor 3-D replays (they plan)


@pytest.mark.slow
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


# ----------------------------------------------------------------------------- damaged cache entries (issue 16, item 6)


def _truncate(b):
    return b[: len(b) * 2 // 3]


def _empty(b):
    return b""


def _garble(b):  # not UTF-8, in the middle of the CSV
    return b[: len(b) // 2] + b"\xff\xfe\x00\x81" + b[len(b) // 2 + 4:]


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory):
    """A whole run of ARGS into a fresh folder (read it, do not write into it: a test
    that reruns copies it): (its folder, its cache entries {(kind, trial): file
    name}, its RunResult)."""
    out = tmp_path_factory.mktemp("undisturbed") / "r"
    result = _run([*ARGS, "--out", str(out)])
    entries = {}
    for path in sorted([*(out / "cache").glob("effort-*.csv"), *(out / "cache").glob("riskruns-*.csv")]):
        entries[path.name.split("-")[0], read_entry(path)["trial"].iloc[0]] = path.name
    assert len(entries) == 6
    return out, entries, result


def _without_wall_clock(path):
    df = pd.read_csv(path, skiprows=1 if path.parent.name == "cache" else 0)
    return df.drop(columns=[c for c in df if c.endswith("_time") and c != "sim_time"])


@pytest.mark.slow
@pytest.mark.parametrize("damage, effort_trial, risk_trial", [(_truncate, "9E", "10E"), (_empty, "10E", "6H"), (_garble, "6H", "9E")])
def test_damaged_cache_entries_are_recomputed_exactly_and_the_run_ends_the_same(undisturbed, tmp_path, capsys, damage, effort_trial, risk_trial):
    whole, entries, _ = undisturbed
    out = tmp_path / "r"
    shutil.copytree(whole, out)
    damaged = {out / "cache" / entries["effort", effort_trial], out / "cache" / entries["riskruns", risk_trial]}
    for path in damaged:
        path.write_bytes(damage(path.read_bytes()))
    capsys.readouterr()

    result = _run([*ARGS, "--out", str(out)])
    err = capsys.readouterr().err
    reported = [l for l in err.splitlines() if "damaged entry" in l]
    assert len(reported) == 2 and {p for p in damaged if any(str(p) in l for l in reported)} == damaged
    assert _cache_counts(result) == {("effort", "hit"): 2, ("effort", "miss"): 0, ("effort", "recomputed"): 1,
                                  ("riskruns", "hit"): 2, ("riskruns", "miss"): 0, ("riskruns", "recomputed"): 1}

    # Every result file and every cache entry is byte-identical to the undisturbed
    # run's, except the wall-clock column of the re-planned effort entry (solve_time).
    for name in ("effort.csv", "risk.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    replanned = out / "cache" / entries["effort", effort_trial]
    pairs = [(out / "cache" / name, whole / "cache" / name) for name in entries.values()]
    for path, reference in pairs + [(out / "effort_samples.csv", whole / "effort_samples.csv")]:
        if path in (replanned, out / "effort_samples.csv"):
            pd.testing.assert_frame_equal(_without_wall_clock(path), _without_wall_clock(reference))
        else:
            assert path.read_bytes() == reference.read_bytes(), path.name
    # the repaired entries are used by the next run
    assert _cache_counts(_run([*ARGS, "--out", str(out)]))["effort", "hit"] == 3


def _fails_naming(capsys, call, error, text):
    """`call()` fails with `error` mentioning `text`: raised, or (with a one-line CLI
    wrapper) printed on stderr with a non-zero exit status."""
    try:
        status = call()
    except error as e:
        message = str(e)
    else:
        assert status != 0
        message = capsys.readouterr().err
    assert text in message, message


def test_problems_are_found_before_the_effort_stage(tmp_path, monkeypatch, capsys):
    """An unstable B and a header-only human-data file stop the run before any
    effort is planned; B's check is one cached simulation per trial."""
    import yaml

    import stimuli
    from analysis import HumanDataError
    from models.risk import UnstableSceneError

    folder = tmp_path / "trials"
    folder.mkdir()
    data = yaml.safe_load((stimuli.TRIAL_DIR / "6E.yaml").read_text())  # a 5-tower -> a row of 5
    data.update(id="13E", pair=13, level="E")
    data["target"]["blocks"] = [{"name": "b1", "p_WB": [0.35, 0.0, 0.0127]},
                                {"name": "b2", "p_WB": [0.35 + 0.7 * 0.0254, 0.0, 0.0381]}]  # overhangs 70 %
    (folder / "13E.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.setattr(stimuli, "TRIAL_DIR", folder)

    def no_effort(*a, **k):
        raise AssertionError("the effort stage started")

    monkeypatch.setattr(app_run, "effort_tables", no_effort)
    args = ["--trials", "13E", "--samples", "1", "--n-sims", "2", "--jobs", "1", "--out", str(tmp_path / "r")]
    _fails_naming(capsys, lambda: reproduce.main(args), UnstableSceneError, "13E-B: unstable before any noise")

    monkeypatch.setattr(models.risk, "check_stable", no_effort)  # the verdict now comes from the cache
    _fails_naming(capsys, lambda: reproduce.main(args), UnstableSceneError, "block b2 moved")

    header_only = tmp_path / "header.csv"
    header_only.write_text("dataset,participant,trial,response\n")
    _fails_naming(capsys, lambda: reproduce.main(["--human-data", str(header_only), *args]),
                  HumanDataError, "no responses after the header")


def test_the_run_config_is_built_once_with_every_default_from_its_one_place():
    """Issue 21: one RunConfig from the command line instead of getattr(args, name,
    default) with retyped defaults; --quick's values and the paper's come from
    lgp.app.config.QUICK and lgp.paper, the fall rule from models.risk, the design
    from lgp.planner.design."""
    from lgp.app.config import QUICK, RunConfig
    from lgp.paper import N_BOOT, N_SIMS, SAMPLES, SIGMA_GRID
    from lgp.planner.design import APPROACH, SLICES_PER_PHASE, Design
    from models.risk.model import DEFAULT_MODEL

    full = reproduce.parse_args([])
    assert isinstance(full, RunConfig)
    assert (full.samples, full.n_sims, full.sigmas, full.n_boot) == (SAMPLES, N_SIMS, SIGMA_GRID, N_BOOT)
    assert full.risk_model == DEFAULT_MODEL
    assert full.design == Design(APPROACH, SLICES_PER_PHASE) and full.planner_choice() == {}
    quick = reproduce.parse_args(["--quick", "--trials", "7h", "7H", "1E", "--sigmas", "0.05", "0.05", "0.1"])
    assert (quick.samples, quick.n_sims, quick.n_boot) == (QUICK["samples"], QUICK["n_sims"], QUICK["n_boot"])
    assert quick.trials == ("7H", "1E") and quick.sigmas == (0.05, 0.1)
    assert quick.command == "python -m lgp.reproduce --quick --trials 7h 7H 1E --sigmas 0.05 0.05 0.1"
    assert RunConfig.from_args(quick) == quick  # nothing left to fill in
    assert reproduce.parse_args(["--samples", "7", "--quick"]).samples == 7  # given beats --quick
    with pytest.raises(dataclasses.FrozenInstanceError):
        full.samples = 3

"""A run is a value: `lgp.app.run.run(config) -> RunResult`, and the writers
(lgp.app.write.write_all) only write what it holds. A feature beyond the paper is a
stage returning data plus a renderer; the manifest's parameters are the RunConfig's."""
import dataclasses
import os

import numpy as np
import pandas as pd
import pytest

import stimuli
from lgp.app.config import RunConfig
from lgp.app.result import Rendered, RunRecord, RunResult, Section

TRIALS = ("9E", "9H", "10E")


def _record() -> RunRecord:
    return RunRecord(stages={"effort": 1.0, "risk": 2.0}, cache_counts={("effort", "hit"): 3, ("riskruns", "miss"): 3},
                     cache_files={("picture", "hit"): 3}, cache_root="cache", compute=(4.0, 0),
                     software={"libraries": {"numpy": np.__version__}, "engine": {"engine": "mujoco", "timestep": 0.002}},
                     recorded_libraries={"numpy": np.__version__}, finished="2026-01-01 00:00 UTC", machine="m, 2 cores",
                     load="load average 0.00", elapsed=5.0)


def _result(sections=()) -> RunResult:
    """A RunResult of three trials with made-up numbers (the writers do not care where they came from)."""
    from models.risk.precision import required_precision

    trials = [stimuli.load_trial(t) for t in TRIALS]
    config = RunConfig(trials=TRIALS, samples=2, n_sims=4, sigmas=(0.05, 0.1), command="python -m lgp.reproduce (test)")
    samples = pd.DataFrame([{"trial": t, "sample": s, "effort": 0.1 + 0.01 * k + 0.001 * s, "n_actions": 4}
                            for k, t in enumerate(TRIALS) for s in range(2)])
    effort = samples.groupby("trial", sort=False)["effort"].mean().reset_index()
    runs = pd.DataFrame([{"trial": t, "sigma": s, "run": r, "fell": bool(r < k * s * 20)}
                         for k, t in enumerate(TRIALS) for s in (0.05, 0.1) for r in range(4)])
    risk = runs.groupby(["trial", "sigma"], sort=False)["fell"].mean().rename("risk").reset_index()
    return RunResult(config, trials, samples, effort, risk, required_precision(runs, n_boot=20), 0.1, None, None,
                     None, False, list(sections), None, None, {"risk.md": "# Risk\n"}, record=_record())


def test_the_writers_write_the_run_results_tables_as_they_are(tmp_path):
    """effort, risk and precision files hold exactly the RunResult's tables."""
    from lgp.app.write import write_all

    result = _result()
    write_all(result, tmp_path)
    for name, table in (("effort_samples", result.effort_samples), ("effort", result.effort), ("risk", result.risk),
                        ("risk_precision", result.precision)):
        shown = [c for c in table if table[c].notna().any()]  # an all-None column reads back as NaN
        pd.testing.assert_frame_equal(pd.read_csv(tmp_path / f"{name}.csv", dtype={"trial": str})[shown], table[shown],
                                      check_dtype=False)
    assert "this run took 5 s" in (tmp_path / "report.md").read_text()  # the record's time, not the writer's clock


def test_the_writers_read_nothing_from_the_folder_they_write(tmp_path):
    """A folder holding a FIFO and a table by one of the run's names: the page and
    report are written from the RunResult alone (opening the FIFO would hang)."""
    from bench.common import deadline
    from lgp.app.write import write_all

    os.mkfifo(tmp_path / "build_risk.csv")
    pd.DataFrame({"trial": ["9E"], "x": [123456]}).to_csv(tmp_path / "risk_sensitivity.csv", index=False)
    with deadline(60):
        write_all(_result(), tmp_path)
    page = (tmp_path / "index.html").read_text()
    assert "123456" not in page and "risk sensitivity" not in page


def test_a_new_section_is_a_stage_and_a_renderer(tmp_path):
    """A section's renderer gets its data and the folder; what it returns lands in the
    report, on the page after the pair tables, and on the trial cards."""
    from lgp.app.write import write_all

    def render(data, view):
        path = view.out / "novelty.csv"
        data.to_csv(path, index=False)
        return Rendered([path], "## Novelty\n\nrows: %d\n" % len(data), '<section id="novelty">novel</section>',
                        card_tables={"novelty": data})

    data = pd.DataFrame({"trial": ["9H"], "score": [0.5]})
    write_all(_result([Section("novelty", data, render)]), tmp_path)
    assert "## Novelty\n\nrows: 1" in (tmp_path / "report.md").read_text()
    page = (tmp_path / "index.html").read_text()
    assert page.index('<section id="novelty">') < page.index('<section id="trials">')
    card = page[page.index('id="trial-9H"'):page.index('id="trial-10E"')]
    assert "novelty (1 rows)" in card


def test_the_run_registers_each_stage_with_its_renderer():
    """Every feature stage declares its name and phase and is paired with a callable renderer."""
    from lgp.app.run import stages

    found = stages()
    assert [s.name for s, _ in found] == ["sensitivity", "build_risk", "recovery", "sigma_from", "participant_sigma"]
    assert all(s.phase in ("compute", "analysis") and callable(r) for s, r in found)
    assert [s.enabled(RunConfig(build_risk=True)) for s, _ in found] == [False, True, False, False, False]


def test_the_page_shows_the_linked_sigma_beside_the_fitted_one():
    """--sigma-from on the page: the linked sigma with its interval, the run's and the
    fitted sigma side by side, and the pair table at the linked sigma."""
    from lgp.app.sigma_from import SigmaBeside, SigmaFrom
    from lgp.app.sigma_from_view import page_html, render

    link = SigmaFrom(0.12, (0.09, 0.18), 0.7, 2, "summary.json")
    pairs = pd.DataFrame({"pair": [1], "dimension": ["height"], "sigma": [0.12], "effort_E": [0.1], "effort_H": [0.2],
                          "effort_rel_diff": [1.0], "risk_E": [0.0], "risk_H": [0.1], "effort_order": ["E<H"],
                          "risk_order": ["E<H"], "effort_E_lt_H": [True], "risk_E_lt_H": [True],
                          "ratio_low": [0.0], "ratio_high": [np.inf], "ratio_tie": [False], "ratio_empty": [False]})
    from analysis.pairs import RATIO_COLUMNS

    pairs = pairs.rename(columns=dict(zip(["ratio_low", "ratio_high", "ratio_tie", "ratio_empty"], RATIO_COLUMNS)))
    html = page_html(SigmaBeside(link, 0.065, 0.08, pairs))
    assert "0.12 d" in html and "[0.09, 0.18]" in html and "0.065 d" in html and "0.08 d" in html
    assert "Pairs at sigma = 0.12 d" in html
    no_fit = render(SigmaBeside(link, 0.065, None, None), None)
    assert "fitted" not in no_fit.page and "No pair table at this sigma" in no_fit.report


def test_the_manifest_parameters_are_the_run_configs():
    """Every RunConfig setting (but the command) is in the manifest, with the trials the
    run resolved; where and how it ran (out, jobs) does not change the input hash."""
    from lgp.app.manifest import manifest_record

    result = _result()
    record = manifest_record(result, 1.0)
    fields = [f.name for f in dataclasses.fields(RunConfig) if f.name != "command"]
    assert list(record["parameters"])[:len(fields)] == fields
    assert record["parameters"]["trials"] == list(TRIALS) and record["parameters"]["sigmas"] == [0.05, 0.1]
    moved = dataclasses.replace(result, config=dataclasses.replace(result.config, out="elsewhere", jobs=1))
    assert manifest_record(moved, 2.0)["input_hash"] == record["input_hash"]
    other = dataclasses.replace(result, config=dataclasses.replace(result.config, seed=1))
    assert manifest_record(other, 1.0)["input_hash"] != record["input_hash"]


def test_the_analysis_computes_without_writing_and_writes_what_run_analysis_writes(tmp_path, make_effort, make_risk):
    """compute_analysis writes nothing; write_analysis of its result gives the files
    and tables run_analysis gives, byte for byte."""
    from analysis.run import compute_analysis, run_analysis, write_analysis

    effort, risk = make_effort(), make_risk()
    result = compute_analysis(None, effort, risk, seed=0, figures=False)
    assert list(tmp_path.iterdir()) == []
    written = write_analysis(result, tmp_path / "a")
    direct = run_analysis(None, effort, risk, tmp_path / "b", seed=0, figures=False)
    assert sorted(os.listdir(tmp_path / "a")) == sorted(os.listdir(tmp_path / "b")) and set(written) == set(direct)
    for name in os.listdir(tmp_path / "a"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


@pytest.mark.slow  # a rerun of the session's quick run from its cache
def test_a_rerun_from_the_cache_computes_nothing_and_writes_its_result(quick_run, tmp_path):
    """The RunResult of a rerun: every result table reused, the tables on disk are
    the result's, and the pair table is the paper's 12 pairs at the paper's sigma."""
    from conftest import QUICK_RUN, copy_of_run
    from lgp import reproduce
    from lgp.app.report import pairs_csv_table
    from lgp.paper import PAPER_SIGMA

    out = copy_of_run(quick_run, tmp_path / "again")
    args = [*QUICK_RUN, "--out", str(out), "--no-replays"]
    result = reproduce.reproduce(reproduce.parse_args(args), args)
    assert result.record.misses == 0 and result.record.hits >= 2 * len(result.trials)
    assert result.sigma == PAPER_SIGMA and len(result.pairs) == 12 and result.over_sigma is not None
    assert not result.human and result.sections == []
    pd.testing.assert_frame_equal(pd.read_csv(out / "pairs.csv"), pairs_csv_table(result.pairs).reset_index(drop=True),
                                  check_dtype=False)
    pd.testing.assert_frame_equal(pd.read_csv(out / "risk.csv", dtype={"trial": str}), result.risk, check_dtype=False)
    for name in ("effort.csv", "risk.csv", "pairs.csv", "pairs_over_sigma.csv"):
        assert (out / name).read_bytes() == (quick_run / name).read_bytes(), name

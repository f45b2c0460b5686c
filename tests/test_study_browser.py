"""The paper's experiments run in a real browser by SIMULATED participants.

`python -m stimuli.experiment` builds the Difficulty Estimation and Time Estimation
studies and the Build Task console; headless Chromium (Debian's, via playwright)
opens each from its local file with every network request refused and goes through
it as several simulated participants whose answers come from analysis.simulate's
model (Eq. 1). Each download is captured and imported (`analysis.import_study`),
and the import runs through `lgp.reproduce --quick --human-data` to the fitted
tables. Every dataset here is named simulated-*: none of it is human data.

Skipped, saying why, only when the browser or playwright is missing (.ci/run
installs both). Set LGP_SCREENSHOTS=DIR to keep screenshots, LGP_BENCH_OUT=FILE to
keep the timings (seconds to the first screen and to the first trial, not asserted).
"""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lgp.paper import TRIAL_IDS
from offline_browser import chromium, keep_screenshot, offline_page
from stimuli import experiment as ex

pytestmark = pytest.mark.slow

#: Participant numbers of the estimation tasks: two blocks of two (an even number).
PARTICIPANTS = (0, 1, 2, 3)
TIMINGS: dict[str, list[float]] = {}


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b
    if os.environ.get("LGP_BENCH_OUT"):
        Path(os.environ["LGP_BENCH_OUT"]).write_text(json.dumps(TIMINGS, indent=1) + "\n")




@pytest.fixture(scope="module")
def studies(quick_run_started, suite_studies) -> dict[str, Path]:
    """The three tasks, built once per suite run (conftest.suite_studies: pictures of
    conftest.STUDY_SIZE, shared with tests/test_study_layout.py) while the session's
    --quick run runs (started first: they are independent)."""
    return suite_studies


@pytest.fixture(scope="module")
def results(quick_run) -> Path:
    """The session's small --quick run: the effort and risk tables the simulated
    participants answer from (read only: the analysis below reruns into a copy)."""
    return quick_run


@pytest.fixture(scope="module")
def answers(results) -> pd.DataFrame:
    """SIMULATED responses from Eq. 1 (analysis.simulate) on the run's effort and risk."""
    from analysis.simulate import simulate_participants

    effort = pd.read_csv(results / "effort.csv")
    risk = pd.read_csv(results / "risk.csv")
    return simulate_participants(effort, risk, (0.0, 1.0, 3.0), 0.065, {"difficulty": 4, "time": 4, "build": 2},
                                 noise_sd=0.05, rng=np.random.default_rng(25))


def _to_range(values: np.ndarray, lo: float, hi: float, digits: int = 0) -> np.ndarray:
    """A participant's answers mapped linearly (increasing) onto [lo, hi]: z-scores unchanged up to rounding."""
    v = (values - values.min()) / (values.max() - values.min())
    return np.round(lo + (hi - lo) * v, digits)


def _open(browser, url: str, clock: bool = False):
    page, errors, refused = offline_page(browser, clock=clock, accept_downloads=True)
    t0 = time.perf_counter()
    page.goto(url)
    return page.context, page, errors, refused, t0


def _pictures_loaded(page) -> list:
    """[trial id, start loaded, finish loaded] of the screen's picture pair."""
    page.wait_for_function("Array.from(document.querySelectorAll('.lgp-pair img')).every(i => i.complete)")
    return page.evaluate("[document.querySelector('.lgp-pair').dataset.trial]"
                         ".concat(Array.from(document.querySelectorAll('.lgp-pair img')).map(i => i.naturalWidth > 0))")


def _run_estimation(browser, folder: Path, task: str, participant: int, values: dict[str, float], downloads: Path):
    """One simulated participant through a whole estimation study; returns (trials shown, csv path)."""
    url = (folder / "index.html").resolve().as_uri() + f"?participant={participant}&simulated=1"
    context, page, errors, refused, t0 = _open(browser, url)
    page.wait_for_selector("#jspsych-instructions-next")
    TIMINGS.setdefault(f"{task}: first screen (s)", []).append(round(time.perf_counter() - t0, 3))
    assert page.evaluate("window.LGP_PRELOAD_FAILED") == []
    page.click("#jspsych-instructions-next")
    page.click("#jspsych-instructions-next")
    shown, path = [], None
    n = 2 + len(TRIAL_IDS)
    for k in range(n):
        page.wait_for_selector("#jspsych-html-slider-response-response")
        if k == 0:
            TIMINGS.setdefault(f"{task}: first trial (s, two instruction clicks included)", []).append(round(time.perf_counter() - t0, 3))
        tid, start_ok, finish_ok = _pictures_loaded(page)
        assert start_ok and finish_ok, f"a picture of {tid} did not load"
        shown.append(tid)
        if participant == 0 and k in (0, 5):
            keep_screenshot(page, f"{task}_{k}.png")
        value = values.get(tid, 50 if task == "difficulty" else 30)
        page.fill("#jspsych-html-slider-response-response", str(int(value)))
        page.dispatch_event("#jspsych-html-slider-response-response", "change")
        if k == n - 1:
            with page.expect_download() as dl:
                page.click("#jspsych-html-slider-response-next")
            path = downloads / dl.value.suggested_filename
            dl.value.save_as(path)
        else:
            page.click("#jspsych-html-slider-response-next")
    page.wait_for_selector("#lgp-done")
    keep_screenshot(page, f"{task}_done.png")
    order = page.evaluate("window.LGP_ORDER_SHOWN")
    js_order = page.evaluate(f"window.LGP_ORDER.trialOrder(window.LGP_STUDY.trials, {participant + 2}, 0).map(t => t.id)")
    assert errors == [] and refused == []
    context.close()
    return shown, order, js_order, path


@pytest.fixture(scope="module")
def estimation_runs(browser, studies, answers, tmp_path_factory):
    downloads = tmp_path_factory.mktemp("downloads")
    runs = {}
    for task, (lo, hi) in (("difficulty", (5, 95)), ("time", (5, ex.TIME_MAX_S - 5))):
        sim = answers[answers.dataset == f"simulated-{task}"]
        for k, participant in enumerate(PARTICIPANTS):
            mine = sim[sim.participant == f"sim-{k + 1:03d}"].set_index("trial")["response"].reindex(list(TRIAL_IDS))
            values = dict(zip(TRIAL_IDS, _to_range(mine.to_numpy(), lo, hi)))
            runs[task, participant] = (*_run_estimation(browser, studies[task], task, participant, values, downloads), values)
    return runs


def test_each_participant_sees_the_two_anchors_then_each_of_the_24_trials_once(estimation_runs):
    for (task, participant), (shown, order, _, path, _) in estimation_runs.items():
        assert shown[:2] == ["ANCHOR-EASY", "ANCHOR-HARD"]
        assert sorted(shown[2:]) == sorted(TRIAL_IDS) and len(shown) == 26
        assert shown[2:] == order
        assert path is not None and path.exists()


def test_the_browser_draws_the_documented_order_of_every_participant(estimation_runs, studies):
    """study.js and stimuli.experiment.trial_order (Python) give the same order, bit for bit."""
    config = json.loads((studies["difficulty"] / "study.json").read_text())
    for (task, participant), (shown, _, js_order, _, _) in estimation_runs.items():
        assert shown[2:] == [t["id"] for t in ex.trial_order(config["trials"], participant, 0)]
        assert js_order == [t["id"] for t in ex.trial_order(config["trials"], participant + 2, 0)]


def test_pairs_stay_together_and_their_order_is_counterbalanced(estimation_runs):
    def pairs(seq):
        return [int(t[:-1]) for t in seq[2::2]], [t[-1] for t in seq[2::2]]

    for task in ("difficulty", "time"):
        seqs = {p: estimation_runs[task, p][0] for p in PARTICIPANTS}
        for seq in seqs.values():  # the two trials of a pair come one after the other
            assert all(seq[i][:-1] == seq[i + 1][:-1] for i in range(2, 26, 2))
        # participants 2k and 2k + 1 share the order of the pairs and reverse each pair
        for a, b in ((0, 1), (2, 3)):
            assert pairs(seqs[a])[0] == pairs(seqs[b])[0]
            assert all(x != y for x, y in zip(pairs(seqs[a])[1], pairs(seqs[b])[1]))
        assert pairs(seqs[0])[0] != pairs(seqs[2])[0]  # the pair order differs between blocks
        # over the even number of participants, each pair is seen easy-first by exactly half
        first = {p: dict(zip(*pairs(seqs[p]))) for p in PARTICIPANTS}
        for pair in range(1, 13):
            assert sum(first[p][pair] == "E" for p in PARTICIPANTS) == len(PARTICIPANTS) // 2


def test_each_download_holds_the_answers_given(estimation_runs):
    for (task, participant), (shown, _, _, path, values) in estimation_runs.items():
        rows = list(csv.DictReader(path.open()))
        assert [r["trial"] for r in rows] == shown
        assert {r["simulated"] for r in rows} == {"SIMULATED"} and {r["participant"] for r in rows} == {str(participant)}
        main = [r for r in rows if r["phase"] == "main"]
        assert [int(r["position"]) for r in main] == list(range(1, 25))
        assert {r["condition"] for r in main} == {str(participant % 2)}
        assert all(float(r["response"]) == values[r["trial"]] for r in main)
        assert all(float(r["rt_ms"]) > 0 for r in main)


def _run_build(browser, folder: Path, participant: int, seconds: dict[str, float], downloads: Path, collapse_on: int | None,
               enter_number: bool):
    url = (folder / "index.html").resolve().as_uri() + ("?simulated=1" if enter_number else f"?participant={participant}&simulated=1")
    context, page, errors, refused, _ = _open(browser, url, clock=True)
    page.wait_for_load_state("load")
    page.clock.pause_at(60_000)  # from here on the page's time moves only when the test says so
    if enter_number:
        page.wait_for_selector("#lgp-participant")
        page.fill("#lgp-participant", str(participant))
        page.click(".jspsych-btn")
    page.wait_for_selector(".lgp-text kbd")
    page.keyboard.press(" ")
    shown, path = [], None
    for k in range(len(TRIAL_IDS)):
        attempts = 2 if k == collapse_on else 1
        for attempt in range(attempts):
            page.wait_for_selector(".lgp-console-status:has-text('lay out the Start state')")
            tid, a_ok, b_ok = _pictures_loaded(page)
            assert a_ok and b_ok
            page.keyboard.press(" ")  # the participant starts
            page.wait_for_selector("#lgp-clock")
            if attempt < attempts - 1:
                page.clock.run_for(4000)
                page.keyboard.press("r")  # collapsed: start again
                continue
            page.clock.run_for(int(seconds[tid] * 1000))
            if k == 0 and participant == 0:
                keep_screenshot(page, "build_console.png")
            if k == len(TRIAL_IDS) - 1:
                with page.expect_download() as dl:
                    page.keyboard.press(" ")
                    page.clock.run_for(10)
                path = downloads / dl.value.suggested_filename
                dl.value.save_as(path)
            else:
                page.keyboard.press(" ")  # finished
        shown.append(tid)
    page.wait_for_selector("#lgp-done")
    assert errors == [] and refused == []
    context.close()
    return shown, path


@pytest.fixture(scope="module")
def build_runs(browser, studies, answers, tmp_path_factory):
    downloads = tmp_path_factory.mktemp("build-downloads")
    sim = answers[answers.dataset == "simulated-build"]
    runs = {}
    for k, participant in enumerate((0, 1)):
        mine = sim[sim.participant == f"sim-{k + 1:03d}"].set_index("trial")["response"].reindex(list(TRIAL_IDS))
        seconds = dict(zip(TRIAL_IDS, _to_range(mine.to_numpy(), 20.0, 200.0, 1)))
        runs[participant] = (*_run_build(browser, studies["build"], participant, seconds, downloads,
                                         collapse_on=3 if participant == 0 else None, enter_number=participant == 1), seconds)
    return runs


def test_the_build_console_times_each_build_between_two_key_presses(build_runs, studies):
    config = json.loads((studies["build"] / "study.json").read_text())
    for participant, (shown, path, seconds) in build_runs.items():
        assert shown == [t["id"] for t in ex.trial_order(config["trials"], participant, 0)]
        rows = list(csv.DictReader(path.open()))
        assert [r["trial"] for r in rows] == shown and {r["phase"] for r in rows} == {"main"}
        for r in rows:  # the fake clock advanced exactly the build time between the two presses
            assert abs(float(r["response"]) - seconds[r["trial"]]) < 0.002, r
            assert r["unit"] == "s"
        collapsed = [r for r in rows if r["collapses"] != "0"]
        if participant == 0:  # one collapse, on the 4th trial: recorded, and its 4 s left out of the build time
            assert [(r["trial"], r["collapses"]) for r in collapsed] == [(shown[3], "1")]
            assert abs(float(collapsed[0]["discarded_ms"]) - 4000) < 2
        else:
            assert collapsed == [] and {r["participant_source"] for r in rows} == {"entered"}


def test_the_downloads_import_and_run_through_the_paper_analysis(estimation_runs, build_runs, results, tmp_path):
    from conftest import QUICK_RUN, copy_of_run

    files = [str(run[3]) for run in estimation_runs.values()] + [str(run[1]) for run in build_runs.values()]
    human = tmp_path / "human.csv"
    run = subprocess.run([sys.executable, "-m", "analysis.import_study", *files, "--out", str(human)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    table = pd.read_csv(human)
    assert table.groupby("dataset")["participant"].nunique().to_dict() == {
        "simulated-build": 2, "simulated-difficulty": 4, "simulated-time": 4}
    assert (table.groupby(["dataset", "participant"]).size() == 24).all()
    out = copy_of_run(results, tmp_path / "results")  # the same run's cache: effort and risk are reused
    run = subprocess.run([sys.executable, "-m", "lgp.reproduce", *QUICK_RUN, "--out", str(out), "--human-data", str(human),
                          "--allow-simulated"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    fits = pd.read_csv(out / "analysis" / "simulated_fits.csv")
    assert set(fits["dataset"]) == {"simulated-difficulty", "simulated-time", "simulated-build"}
    # The answers came from Eq. 1 with little noise: the full model fits every dataset closely.
    full = fits[fits["model"] == "full"]
    assert (full["r"] > 0.9).all(), full

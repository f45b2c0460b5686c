"""A designed stimulus set runs as a browser study (issue 34: "the designed set goes
through `stimuli.experiment --stimuli DIR`, tested in Chromium like the paper's study").

A small set is designed once for this file (`stimuli.design`, a few candidates, 4
trials, tiny faithful check, no paper/power/render); `python -m stimuli.experiment
--task difficulty --stimuli DIR` builds its study; headless Chromium (Debian's, via
playwright, every network request refused: tests/offline_browser.py) goes through it
as two SIMULATED participants: the pages load, every picture of the designed trials
renders, the slider takes each answer, and the download (the data CSV) holds the
answers given in the order the study documents (stimuli.experiment.trial_order). A
designed set has no easy/hard pairs: each participant sees the trials in their own
order. Skipped, saying why, only when the browser or playwright is missing.

The same small design, run again with `--scheduler local-dask`, writes the same set
byte for byte (issue 34: "--scheduler works as in lgp.reproduce (Dask), with the same
set from the same seed").
"""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from offline_browser import chromium, keep_screenshot, offline_page
from stimuli import experiment as ex

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
TRIALS = 4
#: A small design that still goes through every step: 40 candidates of seed 3 screened with 20
#: static runs per sigma, 5 finalists, effort from 1 layout, risk from 3 MuJoCo runs at 0.10 and
#: 0.15 d (the prior's ends): the set, not its numbers, is under test here (tests/test_design.py).
DESIGN = ["--candidates", "40", "--trials", str(TRIALS), "--finalists", "5", "--samples", "1", "--n-sims", "3",
          "--screen-runs", "20", "--sigma-prior", "0.1", "0.15", "--no-paper", "--no-power", "--no-render",
          "--jobs", "1", "--seed", "3"]
SIZE = "320x240"  # small pictures: the test is about the study, not the rendering
PARTICIPANTS = (0, 1)


@pytest.fixture(scope="module")
def designed(tmp_path_factory) -> Path:
    """The designed folder (trial files D01.yaml ... beside design.csv, its cache, finalists/)."""
    from stimuli.design.__main__ import main

    out = tmp_path_factory.mktemp("designed") / "set"
    assert main(["--out", str(out), *DESIGN]) == 0
    return out


@pytest.fixture(scope="module")
def study(designed, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("study")
    env = {**os.environ, "LGP_RENDER_CACHE": str(root / "renders"), "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-m", "stimuli.experiment", "--task", "difficulty", "--stimuli", str(designed),
                          "--out", str(root / "difficulty"), "--size", SIZE, "--jobs", "1"],
                         capture_output=True, text=True, env=env, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "no easy/hard pairs" in run.stderr  # a --trials design is unpaired: the study says so
    return root / "difficulty"


@pytest.fixture(scope="module")
def runs(designed, study, tmp_path_factory) -> dict:
    """participant -> (trial ids shown, {trial: answer given}, the downloaded CSV)."""
    downloads = tmp_path_factory.mktemp("downloads")
    out = {}
    with chromium() as browser:
        for participant in PARTICIPANTS:
            url = (study / "index.html").resolve().as_uri() + f"?participant={participant}&simulated=1"
            page, errors, refused = offline_page(browser, accept_downloads=True)
            page.goto(url)
            page.wait_for_selector("#jspsych-instructions-next")
            assert page.evaluate("window.LGP_PRELOAD_FAILED") == []
            page.click("#jspsych-instructions-next")
            page.click("#jspsych-instructions-next")
            shown, answers, path = [], {}, None
            n = 2 + TRIALS
            for k in range(n):
                page.wait_for_selector("#jspsych-html-slider-response-response")
                page.wait_for_function("Array.from(document.querySelectorAll('.lgp-pair img')).every(i => i.complete)")
                tid, sizes = page.evaluate("[document.querySelector('.lgp-pair').dataset.trial, "
                                           "Array.from(document.querySelectorAll('.lgp-pair img')).map(i => [i.naturalWidth, i.naturalHeight])]")
                assert sizes == [[320, 240], [320, 240]], f"{tid}: the pictures A and B did not render ({sizes})"
                shown.append(tid)
                if participant == 0 and k == 2:
                    keep_screenshot(page, "designed_study_trial.png")
                answers[tid] = 10 + 15 * k + participant  # distinct per trial and participant
                page.fill("#jspsych-html-slider-response-response", str(answers[tid]))
                page.dispatch_event("#jspsych-html-slider-response-response", "change")
                if k == n - 1:
                    with page.expect_download() as dl:
                        page.click("#jspsych-html-slider-response-next")
                    path = downloads / f"p{participant}-{dl.value.suggested_filename}"
                    dl.value.save_as(path)
                else:
                    page.click("#jspsych-html-slider-response-next")
            page.wait_for_selector("#lgp-done")
            assert errors == [] and refused == [], (errors, refused)
            page.context.close()
            out[participant] = (shown, answers, path)
    return out


def test_each_participant_sees_the_anchors_then_each_designed_trial_once_in_the_documented_order(designed, study, runs):
    ids = sorted(p.stem for p in designed.glob("*.yaml"))
    assert ids == [f"D{k:02d}" for k in range(1, TRIALS + 1)]
    config = json.loads((study / "study.json").read_text())
    assert sorted(t["id"] for t in config["trials"]) == ids  # the designed set, not the paper's 24
    for participant, (shown, _, _) in runs.items():
        assert shown[:2] == ["ANCHOR-EASY", "ANCHOR-HARD"]
        assert shown[2:] == [t["id"] for t in ex.trial_order(config["trials"], participant, 0)]
        assert sorted(shown[2:]) == ids


def test_the_download_holds_each_answer_given_to_the_designed_trials(runs):
    for participant, (shown, answers, path) in runs.items():
        assert path is not None and path.exists()
        rows = list(csv.DictReader(path.open()))
        assert [r["trial"] for r in rows] == shown
        assert {r["simulated"] for r in rows} == {"SIMULATED"} and {r["participant"] for r in rows} == {str(participant)}
        main = [r for r in rows if r["phase"] == "main"]
        assert [int(r["position"]) for r in main] == list(range(1, TRIALS + 1))
        assert all(float(r["response"]) == answers[r["trial"]] for r in main)
        assert all(r["pair"] == "" for r in main)  # designed with --trials: no pairs



def test_the_same_seed_designs_the_same_set_on_a_dask_cluster(designed, tmp_path):
    # --scheduler local-dask (one worker process) against the serial run of the fixture:
    # the screen, the finalists' checks and the faithful stages run on Dask's worker, and
    # the set, its tables and its discards come out byte for byte the same
    from stimuli.design.__main__ import main

    out = tmp_path / "dask"
    assert main(["--out", str(out), *DESIGN, "--scheduler", "local-dask"]) == 0
    names = sorted(p.name for p in designed.glob("*.yaml"))
    assert names == sorted(p.name for p in out.glob("*.yaml"))
    for name in names + ["design.csv", "finalists.csv", "discards.csv"]:
        assert (out / name).read_bytes() == (designed / name).read_bytes(), name

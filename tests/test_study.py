"""The study's order and counterbalancing, its command line's refusals, the importer's
checks, and the renderer's camera (the browser runs are in test_study_browser.py).

Every response file made here is marked SIMULATED: none of it is human data.
"""
from __future__ import annotations

import csv
import io
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

import stimuli
from analysis import import_study
from lgp.paper import TRIAL_IDS
from stimuli import experiment as ex
from stimuli import render

TRIALS = [{"id": t, "pair": int(t[:-1]), "level": t[-1]} for t in TRIAL_IDS]


# ----------------------------------------------------------------------------- order


def test_every_participant_sees_each_trial_once_with_a_pairs_two_trials_one_after_the_other():
    for p in range(40):
        order = ex.trial_order(TRIALS, p)
        ids = [t["id"] for t in order]
        assert sorted(ids) == sorted(TRIAL_IDS) and [t["position"] for t in order] == list(range(1, 25))
        assert all(ids[i][:-1] == ids[i + 1][:-1] for i in range(0, 24, 2))
        assert {t["condition"] for t in order} == {p % 2}


def test_participants_2k_and_2k_plus_1_reverse_every_pair_so_each_block_is_balanced():
    for k in range(20):
        a, b = ([t["id"] for t in ex.trial_order(TRIALS, 2 * k + c)] for c in (0, 1))
        assert [t[:-1] for t in a] == [t[:-1] for t in b]
        assert all(x != y for x, y in zip(a, b))


def test_the_order_of_the_pairs_differs_between_blocks_and_easy_first_is_drawn_per_pair():
    pair_orders = {tuple(t["pair"] for t in ex.trial_order(TRIALS, 2 * k)[::2]) for k in range(30)}
    assert len(pair_orders) == 30  # 12! orders: 30 blocks draw 30 different ones
    # Within a block's first participant, about half of the pairs come easy first (not all: not a fixed rule).
    share = [sum(t["first_in_pair"] == "E" for t in ex.trial_order(TRIALS, 2 * k)[::2]) for k in range(200)]
    assert 5.0 < np.mean(share) < 7.0 and min(share) < 12 and max(share) > 0


def test_the_generator_is_mulberry32():
    """Against mulberry32 written out from its definition with Python integers (the
    browser test compares study.js's draws with ex.trial_order's)."""
    def reference(seed, n):
        out, a = [], seed
        for _ in range(n):
            a = (a + 0x6D2B79F5) % 2**32
            t = a
            t = ((t ^ (t >> 15)) * (t | 1)) % 2**32
            t = t ^ ((t + ((t ^ (t >> 7)) * (t | 61)) % 2**32) % 2**32)
            out.append((t ^ (t >> 14)) / 2**32)
        return out

    for seed in (0, 1, 12345, 2**32 - 1):
        draw = ex.mulberry32(seed)
        assert [draw() for _ in range(50)] == reference(seed, 50)
    assert ex.block_seed(0, 5) == 5 and ex.block_seed(1, 0) == 0x9E3779B1 and ex.block_seed(2, 0) == (2 * 0x9E3779B1) % 2**32


def test_without_pairs_every_participant_has_an_own_shuffle_and_no_condition():
    lone = [{"id": f"G{k:04d}", "pair": None, "level": None} for k in range(1, 9)]
    orders = [tuple(t["id"] for t in ex.trial_order(lone, p)) for p in range(10)]
    assert len(set(orders)) == 10 and all(sorted(o) == [t["id"] for t in lone] for o in orders)
    assert {t["condition"] for p in range(10) for t in ex.trial_order(lone, p)} == {0}
    assert ex.units_of(lone)[1] is False and ex.units_of(TRIALS)[1] is True


# ----------------------------------------------------------------------------- the command line refuses


def _refuses(capsys, argv, needle: str):
    from stimuli.experiment.__main__ import main

    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1 and "python -m stimuli.experiment: error:" in err, err
    assert needle in err, err
    return err


def test_the_study_builder_refuses_bad_input_in_one_line_writing_nothing(capsys, tmp_path):
    out = tmp_path / "study"
    _refuses(capsys, ["--task", "estimate", "--out", str(out)], "invalid choice: 'estimate'")
    empty = tmp_path / "empty"
    empty.mkdir()
    _refuses(capsys, ["--task", "difficulty", "--out", str(out), "--stimuli", str(empty)], "no trial files")
    _refuses(capsys, ["--task", "time", "--out", str(out), "--anchor-easy", str(tmp_path / "nope.yaml")], "nope.yaml: no such file")
    bad = tmp_path / "bad.yaml"
    bad.write_text("id: ANCHOR-X\ntarget:\n  blocks:\n  - {name: b1, p_WB: [0.35, 0.0, 0.0127]}\n  - {name: b2, p_WB: [0.35, 0.0, 0.02]}\n")
    _refuses(capsys, ["--task", "difficulty", "--out", str(out), "--anchor-hard", str(bad)], "not a valid trial file")
    clash = tmp_path / "7H.yaml"
    clash.write_text(Path(stimuli.TRIAL_DIR / "7H.yaml").read_text())
    _refuses(capsys, ["--task", "difficulty", "--out", str(out), "--anchor-hard", str(clash)], "is one of the study's trials")
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    _refuses(capsys, ["--task", "build", "--out", str(a_file)], "not a directory")
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "thesis.tex").write_text("keep me")
    _refuses(capsys, ["--task", "build", "--out", str(busy)], "holds no study")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    import os

    if os.access(locked, os.W_OK):  # root writes anywhere: a path under a file instead
        _refuses(capsys, ["--task", "build", "--out", str(a_file / "sub")], "not a directory")
    else:
        _refuses(capsys, ["--task", "build", "--out", str(locked / "study")], "not writable")
    assert not out.exists() and sorted(p.name for p in busy.iterdir()) == ["thesis.tex"]


# ----------------------------------------------------------------------------- the importer


STUDY = "abc123abc123"


def _study_csv(participant: int, task: str = "difficulty", study: str = STUDY, trials=None, simulated=True) -> str:
    """A file as study.js writes it (SIMULATED answers: position + participant)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=ex.COLUMNS, lineterminator="\n")
    w.writeheader()
    base = {c: "" for c in ex.COLUMNS} | {"study": study, "task": task, "participant": participant, "participant_source": "url",
                                         "simulated": "SIMULATED" if simulated else "", "n_trials": 24, "build": "b", "jspsych": "8.3.0"}
    if task != "build":
        for k, a in enumerate(("ANCHOR-EASY", "ANCHOR-HARD"), start=1):
            w.writerow(base | {"phase": "anchor", "position": k, "trial": a, "response": 50, "rt_ms": 900})
    for t in trials or ex.trial_order(TRIALS, participant):
        w.writerow(base | {"phase": "main", "position": t["position"], "trial": t["id"], "condition": t["condition"],
                           "first_in_pair": t["first_in_pair"], "response": t["position"] + participant, "rt_ms": 1000 + t["position"]})
    return buf.getvalue()


def _write(path: Path, text: str) -> str:
    path.write_text(text)
    return str(path)


def test_downloads_of_all_three_tasks_become_the_human_data_format(tmp_path):
    from analysis import load_human_data

    files = [_write(tmp_path / f"{task}-{p}.csv", _study_csv(p, task)) for task in ("difficulty", "time", "build") for p in (0, 1)]
    rows = import_study.import_files(files)
    out = import_study.write_human_data(rows, tmp_path / "human.csv")
    human = load_human_data(out, allow_simulated=True)
    assert human.groupby("dataset")["participant"].nunique().to_dict() == {
        "simulated-build": 2, "simulated-difficulty": 2, "simulated-time": 2}
    assert len(human) == 6 * 24  # the anchors are left out
    one = human[(human.dataset == "simulated-time") & (human.participant == "1")].set_index("trial")
    expected = {t["id"]: t["position"] + 1 for t in ex.trial_order(TRIALS, 1)}
    assert one["response"].to_dict() == expected
    assert one.loc["7H", "source"].startswith("time-1.csv:")


def _import_fails(capsys, files, tmp_path) -> str:
    out = tmp_path / "human.csv"
    code = import_study.cli.run_cli(import_study.main, [*files, "--out", str(out)], prog=import_study.PROG)
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1 and err.startswith("python -m analysis.import_study: error: "), err
    assert not out.exists()
    return err


def test_the_importer_refuses_a_file_of_another_study(capsys, tmp_path):
    a = _write(tmp_path / "a.csv", _study_csv(0))
    b = _write(tmp_path / "b.csv", _study_csv(1, study="other0study0"))
    err = _import_fails(capsys, [a, b], tmp_path)
    assert "b.csv: line 2: from another study ('other0study0', not 'abc123abc123'" in err


def test_the_importer_refuses_a_participant_twice(capsys, tmp_path):
    a = _write(tmp_path / "a.csv", _study_csv(3))
    b = _write(tmp_path / "b.csv", _study_csv(3))
    err = _import_fails(capsys, [a, b], tmp_path)
    assert "b.csv: line 2: participant 3 of the difficulty task again (already in" in err and "a.csv: line 2" in err
    # the same number in another task is another participant
    c = _write(tmp_path / "c.csv", _study_csv(3, "time"))
    assert len(import_study.import_files([a, c])) == 48


def test_the_importer_refuses_a_trial_id_outside_the_24(capsys, tmp_path):
    trials = ex.trial_order(TRIALS, 0)
    trials[5] = {**trials[5], "id": "13E"}
    a = _write(tmp_path / "a.csv", _study_csv(0, trials=trials))
    err = _import_fails(capsys, [a], tmp_path)
    assert "a.csv: line 9: trial '13E' is not one of the 24 trial ids" in err  # header, 2 anchors, then position 6


def test_the_importer_refuses_a_truncated_file_naming_file_and_line(capsys, tmp_path):
    text = _study_csv(0)
    cut = text[: text.index("\n", len(text) // 2) + 10]  # stops in the middle of a row
    a = _write(tmp_path / "cut.csv", cut)
    err = _import_fails(capsys, [a], tmp_path)
    n = cut.count("\n") + 1
    assert f"cut.csv: line {n}: truncated row" in err
    short = "".join(text.splitlines(keepends=True)[:20])  # ends at a row boundary
    b = _write(tmp_path / "short.csv", short)
    err = _import_fails(capsys, [b], tmp_path)
    assert "short.csv: line 20: truncated: participant 0 (difficulty) has 17 of 24 trials" in err


def test_the_importer_refuses_files_that_are_not_study_csvs_and_simulated_mixed_with_real(capsys, tmp_path):
    a = _write(tmp_path / "tidy.csv", "dataset,participant,trial,response\ndifficulty,p1,1E,3\n")
    assert "tidy.csv: line 1: not a study CSV of stimuli.experiment" in _import_fails(capsys, [a], tmp_path)
    sim = _write(tmp_path / "sim.csv", _study_csv(0))
    real = tmp_path / "real.csv"
    real.write_text(_study_csv(1, simulated=False))  # a made-up "real" file, only to be refused here
    err = _import_fails(capsys, [sim, str(real)], tmp_path)
    assert "SIMULATED participants mixed with real ones" in err


def test_the_importer_checks_files_against_the_study_folder(capsys, tmp_path):
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "study.json").write_text(json.dumps({"study": "ffffffffffff", "trials": [{"id": t} for t in TRIAL_IDS]}))
    a = _write(tmp_path / "a.csv", _study_csv(0))
    out = tmp_path / "h.csv"
    code = import_study.cli.run_cli(import_study.main, [a, "--study", str(folder), "--out", str(out)], prog=import_study.PROG)
    assert code == 1 and "from another study ('abc123abc123', not 'ffffffffffff'" in capsys.readouterr().err
    assert not out.exists()


# ----------------------------------------------------------------------------- the renderer's camera


def test_each_trial_has_one_oblique_camera_that_frames_its_start_and_its_finish():
    w, h = render.DEFAULT_SIZE
    scenes: dict[str, list] = {}
    for tid, _, scene in render.pictures_of(stimuli.load_paper(), seed=0, layout="pair"):
        scenes.setdefault(tid, []).append(scene)
    for tid, (A, B) in scenes.items():
        cam = render.trial_camera([A, B], w, h)
        corners = np.vstack([render.scene_corners(A), render.scene_corners(B)])
        uv = cam.project(corners)
        assert (uv[:, 0] > 0).all() and (uv[:, 0] < w).all() and (uv[:, 1] > 0).all() and (uv[:, 1] < h).all(), tid
        # tight: the blocks (or the MIN_AREA square around them) reach within two
        # margins of two opposite edges
        centre = (corners[:, :2].min(axis=0) + corners[:, :2].max(axis=0)) / 2
        square = np.array([[*(centre + np.array([sx, sy]) * render.MIN_AREA / 2), 0.0] for sx in (-1, 1) for sy in (-1, 1)])
        uv = cam.project(np.vstack([corners, square]))
        assert ((uv.max(axis=0) - uv.min(axis=0)) / (w, h)).max() > 1 - 4 * render.MARGIN, tid
        # oblique: the eye is ELEVATION_DEG above the table, and a vertical edge of
        # a block is drawn at least cos(ELEVATION_DEG) - 10 % of its length in pixels
        # relative to a horizontal edge across the view at the same place
        d = np.subtract(cam.eye, cam.target)
        assert np.degrees(np.arcsin(d[2] / np.linalg.norm(d))) == pytest.approx(render.ELEVATION_DEG)
        top, base = cam.project(np.array([[*centre, 0.0254], [*centre, 0.0]]))
        across = cam.project(np.array([[*centre, 0.0], [*(centre + 0.0254 * cam.rotation()[:2, 0] / np.linalg.norm(cam.rotation()[:2, 0])), 0.0]]))
        assert top[1] < base[1] and abs(top[0] - base[0]) < 2
        assert (base[1] - top[1]) / np.linalg.norm(across[1] - across[0]) > np.cos(np.radians(render.ELEVATION_DEG)) - 0.1


def test_the_study_shows_each_pair_its_own_start_and_a_pair_one_start():
    """The layout of A: sample 0 for every trial (the results page, the replay) puts
    one identical scatter in front of 1H, 5E, 5H, 9H and 11E; the study's "pair"
    layout (sample p - 1 for pair p) keeps 5E and 5H together and parts the others."""
    trials = {t.id: t for t in stimuli.load_paper()}
    five = ("1H", "5E", "5H", "9H", "11E")

    def starts(layout):
        return {tid: np.round(np.array([b.p_WB for b in A.blocks]), 9).tobytes()
                for tid, state, A in render.pictures_of([trials[t] for t in five], 0, layout) if state == "A"}

    assert len(set(starts("sample0").values())) == 1
    shown = starts("pair")
    assert shown["5E"] == shown["5H"] and len(set(shown.values())) == 4
    every = {tid: np.round(np.array([b.p_WB for b in A.blocks]), 9).tobytes()
             for tid, state, A in render.pictures_of(list(trials.values()), 0, "pair") if state == "A"}
    for a in every:
        for b in every:
            if a != b and trials[a].pair != trials[b].pair:
                assert every[a] != every[b], (a, b)


def _wood(png) -> np.ndarray:
    """Pixels of the (unpainted, wooden) blocks in a rendered picture: much redder than
    blue, unlike the grey table and its shadows."""
    from PIL import Image

    rgb = np.asarray(Image.open(png).convert("RGB")).astype(int)
    return (rgb[:, :, 0] - rgb[:, :, 2] > 25) & (rgb[:, :, 0] > 60)


@pytest.mark.slow
def test_the_finish_pictures_of_4E_and_4H_and_of_7E_and_7H_are_told_apart(tmp_path):
    """The pictures show what the pairs contrast. 4H's staircase (each block d/5
    further in +x than the one below) leans in the picture and 4E's column does not:
    the top block's outline moves sideways relative to the base by as many pixels as
    the pinhole model of the two cameras predicts (12 px at 480x320), and more than 6.
    7H's tower is tall and narrow (width/height under 0.4), 7E's row wide and low
    (over 2), as the projected corners of their blocks predict."""
    w, h = 480, 320
    trials = [stimuli.load_trial(t) for t in ("4E", "4H", "7E", "7H")]
    scenes: dict[str, list] = {}
    for tid, _, scene in render.pictures_of(trials, 0, "pair"):
        scenes.setdefault(tid, []).append(scene)
    cams = {tid: render.trial_camera(both, w, h) for tid, both in scenes.items()}
    r = render.Renderer(cams["4E"])
    masks, lean = {}, {}
    for tid, (_, B) in scenes.items():
        r.render(B, tmp_path / f"{tid}.png", cams[tid])
        masks[tid] = _wood(tmp_path / f"{tid}.png")
        vs, us = np.nonzero(masks[tid])
        assert len(us) > 200, tid
        top = min(B.blocks, key=lambda b: -b.p_WB[2])
        base = min(B.blocks, key=lambda b: b.p_WB[2])
        predicted = np.subtract(*cams[tid].project(np.array([top.p_WB, base.p_WB]))[:, 0])
        # measured: the mean column of the outline's top rows and bottom rows (a block's height each)
        block_rows = (vs.max() - vs.min()) / len(B.blocks)
        upper, lower = us[vs < vs.min() + 0.6 * block_rows], us[vs > vs.max() - 0.6 * block_rows]
        lean[tid] = (predicted, upper.mean() - lower.mean())
    predicted = lean["4H"][0] - lean["4E"][0]
    measured = lean["4H"][1] - lean["4E"][1]
    assert predicted > 10 and abs(measured - predicted) < 0.35 * predicted and measured > 6, lean
    # 7E and 7H: the outline's extent, width over height, as the projected corners
    # of the blocks predict (within 20 %): the row lies wide, the tower stands tall
    def aspect(uv):
        return (uv[:, 0].max() - uv[:, 0].min()) / (uv[:, 1].max() - uv[:, 1].min())

    shape = {}
    for tid in ("7E", "7H"):
        vs, us = np.nonzero(masks[tid])
        shape[tid] = (aspect(np.column_stack([us, vs])), aspect(cams[tid].project(render.scene_corners(scenes[tid][1]))))
        assert shape[tid][0] == pytest.approx(shape[tid][1], rel=0.2), shape
    assert shape["7E"][0] > 2 and shape["7H"][0] < 0.4 and shape["7E"][0] / shape["7H"][0] > 8, shape


@pytest.mark.slow
def test_a_rendered_block_lies_where_the_camera_model_projects_it(tmp_path):
    """Drake's picture against the pinhole model of Camera.project (independent:
    the model knows nothing of VTK)."""
    from PIL import Image

    from lgp.scene import Block, Scene

    cam = render.Camera((0.0, 0.0, 0.5), (0.40, 0.05, 0.0), render.FOV_Y_DEG, 320, 240)
    r = render.Renderer(cam)
    for p in ([0.40, 0.05, 0.0127], [0.30, -0.10, 0.0127], [0.50, 0.15, 0.0127]):
        r.render(Scene([Block("b", np.array(p), 0.0, "red")], (), "t"), tmp_path / "b.png")
        rgb = np.asarray(Image.open(tmp_path / "b.png")).astype(float)
        red = (rgb[:, :, 0] > 90) & (rgb[:, :, 0] > 2.0 * rgb[:, :, 1])
        vs, us = np.nonzero(red)
        assert len(us) > 20
        top_centre = cam.project(np.array([[p[0], p[1], 0.0254]]))[0]
        corners = cam.project(render.scene_corners(Scene([Block("b", np.array(p), 0.0, "red")], (), "t")))
        assert corners[:, 0].min() - 2 <= us.min() and us.max() <= corners[:, 0].max() + 2
        assert corners[:, 1].min() - 2 <= vs.min() and vs.max() <= corners[:, 1].max() + 2
        assert abs(np.median(us) - top_centre[0]) < 4


@pytest.mark.slow
def test_a_stimulus_folder_without_pairs_builds_with_pair_counterbalancing_off(tmp_path, monkeypatch, capsys):
    """Generated trials (G0001 ...) form no easy/hard pair: the study says so and
    gives each participant their own shuffle."""
    from lgp.cli import run_cli
    from stimuli.experiment.__main__ import PROG, main as experiment
    from stimuli.generate import main as generate

    monkeypatch.setenv("LGP_RENDER_CACHE", str(tmp_path / "renders"))
    assert generate(["--out", str(tmp_path / "gen"), "--count", "3", "--seed", "1"]) == 0
    capsys.readouterr()
    # the command's main and run_cli wrapper in this process (a fresh interpreter re-imports the renderer, ~2.5 CPU-s)
    code = run_cli(experiment, ["--task", "difficulty", "--out", str(tmp_path / "study"), "--stimuli", str(tmp_path / "gen"),
                                "--size", "96x64"], prog=PROG)
    err = capsys.readouterr().err
    assert code == 0, err
    assert "pair counterbalancing is off" in err
    config = json.loads((tmp_path / "study" / "study.json").read_text())
    assert config["pair_counterbalancing"] is False and [t["id"] for t in config["trials"]] == ["G0001", "G0002", "G0003"]
    pictures = sorted(p.name for p in (tmp_path / "study" / "img").iterdir())
    assert pictures == sorted(f"{t}-{s}.png" for t in ("G0001", "G0002", "G0003", "ANCHOR-EASY", "ANCHOR-HARD") for s in "AB")
    assert (tmp_path / "study" / "lib" / "jspsych.js").stat().st_size > 10_000


@pytest.mark.slow  # renders on a pool and fresh, ~2 s
def test_pictures_rendered_on_a_runs_workers_equal_those_of_fresh_processes(tmp_path):
    # lgp.reproduce renders the page's pictures on its own warm workers
    # (render_trials(executor=...)); the pixels are those the standalone path makes.
    from PIL import Image

    from lgp.executor import ProcessExecutor

    trials = [stimuli.load_trial(t) for t in ("7H", "12E")]
    fresh = render.render_trials(trials, tmp_path / "fresh", 0, (160, 120), jobs=1, log=lambda m: None)
    with ProcessExecutor(2) as ex:
        warm = render.render_trials(trials, tmp_path / "warm", 0, (160, 120), log=lambda m: None, executor=ex)
    assert warm["rendered"] == fresh["rendered"] == 4
    for row in fresh["pictures"]:
        a = np.asarray(Image.open(tmp_path / "fresh" / row["file"]))
        b = np.asarray(Image.open(tmp_path / "warm" / row["file"]))
        assert a.shape == b.shape and np.array_equal(a, b), row["file"]

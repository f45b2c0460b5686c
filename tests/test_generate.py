"""python -m stimuli.generate writes valid trials whose B stands, the same files for
the same seed, and python -m lgp.reproduce --stimuli DIR runs them end to end
(pair table only for pairs whose E and H files are both in DIR)."""
import os
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

import stimuli
from lgp.paper import BLOCK_SIZE as d
from models.risk.static import static_stable
from stimuli.generate import KINDS, generate, structure, trial_data

ROOT = Path(__file__).resolve().parents[1]


def test_generated_trials_load_and_their_targets_stand_by_the_static_criterion(tmp_path):
    paths = generate(tmp_path, 10, seed=3)
    assert [p.name for p in paths] == [f"G{i:04d}.yaml" for i in range(1, 11)]
    for path in paths:
        trial = stimuli.load_file(path)
        assert trial.pair is None and trial.level is None
        assert len(trial.initial.scattered) == len(trial.target)  # every block of B starts scattered in A
        # engine-free check (the generator used the physics check): centre of mass over the support
        if not trial.description.split("-> ")[1].startswith(("bridge", "pyramid")):  # shared loads: heuristic only there
            assert static_stable(trial.target), trial


def test_same_seed_same_files_and_a_prefix_is_the_smaller_set(tmp_path):
    a = generate(tmp_path / "a", 4, seed=11)
    b = generate(tmp_path / "b", 6, seed=11)
    assert [p.read_bytes() for p in a] == [p.read_bytes() for p in b[:4]]
    c = generate(tmp_path / "c", 4, seed=12)
    assert [p.read_bytes() for p in a] != [p.read_bytes() for p in c]


def test_the_kinds_and_sizes_the_generator_promises():
    kinds = Counter(trial_data(i, 0)["dimension"].split(": ")[1] for i in range(200))
    assert set(kinds) == set(KINDS)
    import numpy as np

    towers = {len(structure("tower", np.random.default_rng(k))[0]) for k in range(300)}
    assert towers == set(range(2, 13))
    bridge, _ = structure("bridge", np.random.default_rng(0))
    pillars = sorted({round(y / d, 6) for _, y, z in bridge if z < bridge[-1][2] and abs(y) > 0})
    assert pillars == [-0.75, 0.75]  # 1.5 d between pillar centres: a gap of 0.5 d


def _reproduce(capsys, *args) -> subprocess.CompletedProcess:
    """`python -m lgp.reproduce ARGS` in this process (its imports paid once): the exit
    status and stderr its command line gives (lgp.cli.run_cli)."""
    from lgp import cli, reproduce

    capsys.readouterr()
    code = cli.run_cli(reproduce.main, list(args), prog=reproduce.PROG)
    return subprocess.CompletedProcess(args, code, "", capsys.readouterr().err)


@pytest.mark.slow
def test_reproduce_runs_a_generated_set_and_pairs_only_what_files_declare(tmp_path, capsys):
    generate(tmp_path / "set", 2, seed=5)
    for tid in ("1E", "1H"):  # one declared pair beside the generated trials
        shutil.copy(stimuli.TRIAL_DIR / f"{tid}.yaml", tmp_path / "set")
    r = _reproduce(capsys, "--stimuli", str(tmp_path / "set"), "--out", str(tmp_path / "out"), "--samples", "1", "--n-sims", "2",
                   "--sigmas", "0.05", "--no-replays", "--jobs", "1")
    assert r.returncode == 0, r.stderr[-2000:]
    effort = pd.read_csv(tmp_path / "out" / "effort.csv", dtype={"trial": str})
    assert list(effort["trial"]) == ["1E", "1H", "G0001", "G0002"]
    assert effort["pair"].isna().tolist() == [False, False, True, True]
    assert len(pd.read_csv(tmp_path / "out" / "risk.csv")) == 4
    pairs = pd.read_csv(tmp_path / "out" / "pairs.csv")
    assert pairs["pair"].tolist() == [1]
    assert pairs["effort_E"].iloc[0] == effort.set_index("trial").loc["1E", "effort"]


@pytest.mark.slow  # the pipeline's imports
def test_a_stimulus_directory_without_trial_files_is_one_line(tmp_path, capsys):
    r = _reproduce(capsys, "--stimuli", str(tmp_path), "--out", str(tmp_path / "out"))
    assert r.returncode == 1
    assert r.stderr.strip().splitlines()[-1] == f"python -m lgp.reproduce: error: --stimuli {tmp_path}: no trial files (*.yaml) there"


def test_a_bad_generated_count_is_refused():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "stimuli.generate", "--out", "/tmp/x", "--count", "0"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "argument --count: must be a whole number >= 1" in r.stderr, r.stderr


def test_a_users_file_with_a_generated_name_is_never_replaced_or_deleted(tmp_path):
    """A folder holding the user's own G0002.yaml is refused before any draw: the file
    stays byte-identical and no other trial is written beside it."""
    mine = tmp_path / "G0002.yaml"
    mine.write_bytes(b"# my hand-made trial\n")
    with pytest.raises(ValueError, match="G0002.yaml"):
        generate(tmp_path, 3, seed=0)
    assert mine.read_bytes() == b"# my hand-made trial\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["G0002.yaml"]


@pytest.mark.slow
def test_the_cli_refuses_a_folder_holding_a_generated_name_in_one_line(tmp_path):
    mine = tmp_path / "G0002.yaml"
    mine.write_bytes(b"# my hand-made trial\n")
    run = subprocess.run([sys.executable, "-m", "stimuli.generate", "--out", str(tmp_path), "--count", "3"],
                         capture_output=True, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 1 and run.stderr.count("\n") == 1 and "G0002.yaml" in run.stderr
    assert mine.read_bytes() == b"# my hand-made trial\n"

"""Bad inputs from an adversarial user: each is
refused at the boundary in one named line, quickly, before anything is
allocated by its size or any earlier output is removed.

Every case runs under a deadline (SIGALRM), so code that would read /dev/zero
or wait on a FIFO forever fails the test instead of hanging the suite."""
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import stimuli
from analysis.data import TRIAL_IDS, HumanDataError, load_human_data
from bench.common import deadline  # one SIGALRM deadline for the probe (bench/faults.py) and these tests
from lgp.inputs import InputFileError, read_bounded
from stimuli import StimulusError

ROOT = Path(__file__).resolve().parents[1]
BASE = (stimuli.TRIAL_DIR / "1E.yaml").read_text()


def _trial_dir(tmp_path, name="X1.yaml", text=None):
    folder = tmp_path / "trials"
    folder.mkdir(exist_ok=True)
    if text is not None:
        (folder / name).write_text(text)
    return folder


X1 = BASE.replace("id: 1E\npair: 1\nlevel: E\n", "id: X1\n")


# ----------------------------------------------------------------------------- item 4: one bounded reader


def test_the_bounded_reader_reads_at_most_its_limit_even_when_the_size_lies():
    """/proc files report size 0 and are regular: the reader must count what it reads."""
    data = read_bounded("/proc/self/maps", 1 << 20)
    assert data.count(b"\n") > 3
    with pytest.raises(InputFileError, match="more than the 16 bytes allowed"):
        read_bounded("/proc/self/maps", 16)


def test_a_trial_file_linked_to_dev_zero_is_refused_before_reading(tmp_path):
    folder = _trial_dir(tmp_path)
    (folder / "X1.yaml").symlink_to("/dev/zero")
    with deadline(5), pytest.raises(StimulusError, match=r"X1.yaml: a character device \(a symbolic link to /dev/zero\), not a regular file"):
        stimuli.load_trial("X1", folder)


def test_a_fifo_named_like_a_trial_file_is_refused_not_waited_on(tmp_path):
    folder = _trial_dir(tmp_path)
    os.mkfifo(folder / "X1.yaml")
    with deadline(5), pytest.raises(StimulusError, match=r"X1.yaml: a FIFO \(named pipe\), not a regular file"):
        stimuli.load_trial("X1", folder)
    with deadline(5), pytest.raises(StimulusError, match="FIFO"):
        stimuli.load_file(folder / "X1.yaml")


def test_a_dangling_symlink_is_named_as_one(tmp_path):
    folder = _trial_dir(tmp_path)
    (folder / "X1.yaml").symlink_to(tmp_path / "gone.yaml")
    with pytest.raises(StimulusError, match=r"X1.yaml is a symbolic link to .*gone.yaml, which does not exist"):
        stimuli.load_trial("X1", folder)


def test_a_lower_case_file_name_says_to_rename_it(tmp_path):
    folder = _trial_dir(tmp_path, "x1.yaml", X1)
    with pytest.raises(StimulusError, match=r"has x1.yaml, but a trial file is named by its id in upper case: rename it X1.yaml"):
        stimuli.load_trial("X1", folder)
    assert stimuli.load_trial("X1", _trial_dir(tmp_path, "X1.yaml", X1)).id == "X1"


def test_human_data_that_is_a_fifo_or_dev_zero_is_refused(tmp_path):
    os.mkfifo(tmp_path / "fifo.csv")
    (tmp_path / "zero.csv").symlink_to("/dev/zero")
    with deadline(5), pytest.raises(HumanDataError, match=r"fifo.csv: a FIFO \(named pipe\), not a regular file"):
        load_human_data(tmp_path / "fifo.csv")
    with deadline(5), pytest.raises(HumanDataError, match=r"zero.csv: a character device"):
        load_human_data(tmp_path / "zero.csv")


# ----------------------------------------------------------------------------- item 5: human data size


def _responses(n_participants, dataset="difficulty", value=None, seed=0):
    rng = np.random.default_rng(seed)
    n = n_participants
    return pd.DataFrame({"dataset": dataset, "participant": np.repeat([f"p{k}" for k in range(n)], 24),
                         "trial": np.tile(TRIAL_IDS, n),
                         "response": rng.normal(size=24 * n) if value is None else value})


def test_human_data_past_the_participant_limit_is_refused_in_one_line(tmp_path):
    path = tmp_path / "h.csv"
    _responses(11).to_csv(path, index=False)
    with pytest.raises(HumanDataError) as e:
        load_human_data(path, max_participants=10)
    assert "11 participants, more than the 10 allowed (--max-participants raises the limit" in str(e.value)
    assert "\n" not in str(e.value)
    assert len(load_human_data(path, max_participants=11)) == 24 * 11


def test_human_data_past_the_byte_limit_is_refused_without_being_read(tmp_path):
    path = tmp_path / "h.csv"
    _responses(2).assign(note="x" * 5000).to_csv(path, index=False)  # 2 participants, 240 kB
    with pytest.raises(HumanDataError, match=r"h.csv: human-data file is \d+ bytes, more than the 48000 allowed"):
        load_human_data(path, max_participants=10)


# ----------------------------------------------------------------------------- item 7: huge counts, crowded regions


def test_a_count_of_a_trillion_is_refused_before_anything_is_allocated(tmp_path):
    text = X1.replace("count: 3", "count: 1000000000000")
    with deadline(5), pytest.raises(StimulusError, match="cannot scatter 1000000000000 blocks"):
        stimuli.load_trial("X1", _trial_dir(tmp_path, text=text))


def _grid_target(n_side, x0=0.2, y0=-0.25, d=0.0254):
    lines = ["target:", "  blocks:"]
    for i in range(n_side):
        for j in range(n_side):
            lines += [f"  - name: t{i}_{j}", f"    p_WB: [{x0 + d / 2 + i * d:.5f}, {y0 + d / 2 + j * d:.5f}, 0.0127]"]
    return "\n".join(lines) + "\n"


def test_the_target_footprint_counts_against_the_scatter_region(tmp_path):
    """A 14 x 14 target floor (0.127 m^2 of blocks) covers the 0.35 x 0.5 region; 100
    scattered blocks fit by area alone but not beside that floor: refused at load."""
    head = X1[: X1.index("target:")].replace("count: 3", "count: 100")
    text = head + _grid_target(14)
    t0 = time.monotonic()
    with deadline(20), pytest.raises(StimulusError, match="covered by the target's blocks and the fixed things"):
        stimuli.load_trial("X1", _trial_dir(tmp_path, text=text))
    assert time.monotonic() - t0 < 10


@pytest.mark.slow  # waits out the sampler's time bound
def test_the_scatter_sampler_gives_up_in_bounded_time_with_one_line(tmp_path, monkeypatch):
    """A region that passes the area bound but jams random placement: the sampler
    stops after SCATTER_SECONDS and says so."""
    monkeypatch.setattr(stimuli.start, "SCATTER_SECONDS", 0.5)  # where the sampler reads it
    text = X1.replace("count: 3", "count: 140").replace("x: [0.2, 0.55]", "x: [-0.2, 0.2]").replace(
        "y: [-0.25, 0.25]", "y: [0.1, 0.5]")
    t0 = time.monotonic()
    with deadline(20), pytest.raises(StimulusError, match=r"no layout found in 0.5 s .*too crowded \(stimuli.start.SCATTER_SECONDS"):
        stimuli.load_trial("X1", _trial_dir(tmp_path, text=text))
    assert time.monotonic() - t0 < 5


# ----------------------------------------------------------------------------- item 12: duplicate keys


def test_a_key_given_twice_is_refused_with_both_lines(tmp_path):
    text = X1.replace("    count: 3\n", "    count: 3\n    count: 30\n")
    with pytest.raises(StimulusError, match=r"line 17: key 'count' given twice in one mapping \(first on line 16\)"):
        stimuli.load_trial("X1", _trial_dir(tmp_path, text=text))
    # the same key in two different mappings is fine (every block has a name)
    assert stimuli.load_trial("X1", _trial_dir(tmp_path, text=X1)).id == "X1"


# ----------------------------------------------------------------------------- item 8: human-data rules up front


def test_every_participant_constant_is_refused_by_name_at_load(tmp_path):
    path = tmp_path / "h.csv"
    pd.concat([_responses(3, value=4.0), _responses(3, "time")]).to_csv(path, index=False)
    with pytest.raises(HumanDataError, match="dataset 'difficulty': every one of its 3 participant.s. gave the same "
                                             "response on every trial, so all are excluded"):
        load_human_data(path)


def test_responses_near_1e_minus_299_are_too_small_not_too_large(tmp_path):
    path = tmp_path / "h.csv"
    tiny = _responses(3)
    tiny["response"] = tiny["response"].abs() * 1e-299
    tiny.to_csv(path, index=False)
    with pytest.raises(HumanDataError) as e:
        load_human_data(path)
    assert "SD underflows to 0" in str(e.value) and "too large" not in str(e.value)


@pytest.mark.slow  # a subprocess pipeline run
def test_bad_human_data_stops_the_run_before_earlier_outputs_are_removed(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "effort.csv").write_text("earlier run\n")
    (out / "manifest.json").write_text('{"files": [{"path": "effort.csv"}]}')
    path = tmp_path / "h.csv"
    _responses(3, value=4.0).to_csv(path, index=False)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "lgp.reproduce", "--quick", "--human-data", str(path), "--out", str(out)],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "every one of its 3 participant(s) gave the same response" in lines[0], r.stderr
    assert (out / "effort.csv").read_text() == "earlier run\n"


# ----------------------------------------------------------------------------- item 12: the risk API's edges


@pytest.mark.parametrize("kwargs, message", [
    ({"sigma": float("inf")}, r"sigma must be a finite number in \[0, 1\].*got inf"),
    ({"sigma": 1e308}, r"sigma must be a finite number in \[0, 1\].*got 1e\+308"),
    ({"sigma": float("nan")}, r"sigma must be a finite number"),
    ({"sigma": 1.5}, r"sigma must be a finite number in \[0, 1\]"),
    ({"sigma": "0.1"}, r"sigma must be a number"),
    ({"n_sims": 2.5}, r"n_sims must be a whole number >= 1 .*got 2.5"),
    ({"n_sims": "4"}, r"n_sims must be a whole number >= 1 .*got '4'"),
    ({"n_sims": True}, r"n_sims must be a whole number >= 1 .*got True"),
    ({"seed": None}, r"seed=None would draw irreproducible numbers"),
    ({"seed": -1}, r"seed must be a whole number >= 0"),
])
def test_physical_risk_refuses_bad_arguments_by_name(kwargs, message):
    import warnings

    from models.risk import physical_risk
    from models.risk.structures import tower

    args = {"sigma": 0.05, "n_sims": 3, "seed": 0, **kwargs}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warnings on the way to the error
        with pytest.raises(ValueError, match=message):
            physical_risk(tower(2), args.pop("sigma"), **args)


def test_the_bootstrap_in_blocks_gives_the_same_numbers_as_all_at_once(monkeypatch):
    """Bounded memory for big files must not change a single resample."""
    import analysis.data.means as data  # where resample_trial_means reads BOOTSTRAP_BLOCK_BYTES
    from analysis.data import resample_trial_means, validate_human_data, zscore_responses

    z = zscore_responses(validate_human_data(_responses(37)))
    whole = resample_trial_means(z, 101, np.random.default_rng(4))
    monkeypatch.setattr(data, "BOOTSTRAP_BLOCK_BYTES", 37 * 24 * 8 * 3)  # three resamples per block
    blocks = resample_trial_means(z, 101, np.random.default_rng(4))
    rng = np.random.default_rng(4)
    Z = data.participant_matrices(z)["difficulty"][1]
    direct = Z[rng.integers(0, 37, size=(101, 37))].mean(axis=1)
    assert np.array_equal(blocks["difficulty"], whole["difficulty"]) and np.array_equal(whole["difficulty"], direct)


@pytest.mark.parametrize("which", ["initial", "target"])
def test_plan_of_none_is_a_named_error(which):
    import lgp
    from lgp.errors import InputError

    B = stimuli.load_trial("1E").target
    args = (None, B) if which == "initial" else (B, None)
    with pytest.raises(InputError, match=rf"lgp.plan: {which} \(state [AB]\) must be an lgp.scene.Scene.*got NoneType"):
        lgp.plan(*args)


def test_the_participant_limit_default_is_one_number():
    from analysis.data import MAX_PARTICIPANTS
    from lgp.app.config import RunConfig

    assert RunConfig().max_participants == MAX_PARTICIPANTS

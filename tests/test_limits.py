"""Counts and sizes bounded at the door: a count on the command line past
its limit is refused in one line with what it would cost (else a
MemoryError after minutes of work); more --jobs than cores are capped, saying so,
unless --oversubscribe; a trial file with a 5000-digit number or 10,000 blocks is
refused in one line naming the limit, before it is built."""
from __future__ import annotations

import os

import pytest

import stimuli
from bench.common import deadline
from lgp import cli
from stimuli import StimulusError

X1 = (stimuli.TRIAL_DIR / "1E.yaml").read_text().replace("id: 1E\npair: 1\nlevel: E\n", "id: X1\n")


def _refusal(capsys, main, argv) -> str:
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1, err
    return err


def _reproduce(argv):
    from lgp.reproduce import parse_args

    return parse_args(argv)


def _risk(argv):
    from models.risk.__main__ import main

    return main(argv)


def _demo(argv):
    from analysis.demo import main

    return main(argv)


def _generate(argv):
    from stimuli.generate import main

    return main(argv)


@pytest.mark.parametrize("main, argv, estimate", [
    (_reproduce, ["--n-sims", "1000000000000"], "= 218 TiB and 24 trials x 11 sigmas x 1,000,000,000,000 = 264,000,000,000,000 simulations"),
    (_reproduce, ["--n-boot", "1000000000000"], "x 8 bytes = 175 TiB per dataset"),
    (_reproduce, ["--samples", "1000000000"], "= 24,000,000,000 KOMO plans, 3.33e+07 times the paper's M = 30"),
    (_reproduce, ["--n-perm", "1000000000"], "1,000,000,000 refits of the model per permutation test"),
    (_risk, ["--n-sims", "1000000000000"], "218 TiB"),
    (_demo, ["--n-boot", "1000000000000"], "175 TiB"),
    (_generate, ["--out", "OUT", "--count", "1000000000000"], "1.82 PiB on disk"),
])
def test_a_count_past_its_limit_is_refused_at_the_door_with_its_cost(capsys, tmp_path, main, argv, estimate):
    argv = [a.replace("OUT", str(tmp_path / "out")) for a in argv]
    with deadline(20):
        err = _refusal(capsys, main, argv)
    assert "is more than the" in err and "allowed (lgp.cli.MAX_" in err and estimate in err, err
    assert not (tmp_path / "out").exists()


def test_the_estimates_are_the_arithmetic_they_state():
    """218 TiB = 1e12 runs x 10 blocks x 3 coordinates x 8 bytes; 175 TiB = 1e12 x 24 x 8."""
    assert abs(1e12 * 240 / 2 ** 40 - 218) < 0.5 and abs(1e12 * 24 * 8 / 2 ** 40 - 175) < 0.5
    assert cli.bytes_text(1023) == "1023 bytes" and cli.bytes_text(1024 ** 3 * 2.24) == "2.24 GiB"


def test_counts_at_the_limit_pass():
    assert cli.bounded_count("MAX_N_SIMS")(str(cli.MAX_N_SIMS)) == cli.MAX_N_SIMS
    assert _reproduce(["--n-boot", str(cli.MAX_N_BOOT), "--samples", str(cli.MAX_SAMPLES)]).n_boot == cli.MAX_N_BOOT


def test_more_jobs_than_cores_are_capped_in_one_line_unless_oversubscribed(capsys):
    cores = cli.usable_cores()
    assert _reproduce(["--jobs", str(cores + 398)]).jobs == cores
    err = capsys.readouterr().err.strip()
    assert err == (f"python -m lgp.reproduce: --jobs {cores + 398} is more than the {cores} usable core(s): "
                   f"using {cores} (--oversubscribe starts them all)")
    assert _reproduce(["--jobs", str(cores + 398), "--oversubscribe"]).jobs == cores + 398
    assert _reproduce(["--jobs", str(cores)]).jobs == cores and capsys.readouterr().err == ""
    # a remote scheduler's workers are not this machine's cores
    assert _reproduce(["--jobs", "400", "--scheduler", "tcp://127.0.0.1:8786"]).jobs == 400


def _trial(tmp_path, text):
    folder = tmp_path / "trials"
    folder.mkdir(exist_ok=True)
    (folder / "X1.yaml").write_text(text)
    return folder


def test_a_5000_digit_number_in_a_trial_file_is_refused_naming_the_limit(tmp_path):
    """It reached Python's int conversion: a ValueError traceback."""
    folder = _trial(tmp_path, X1.replace("count: 3", "count: " + "9" * 5000))
    with pytest.raises(StimulusError, match=r"X1.yaml: line \d+: a number of 5000 characters \(9+\.\.\.\), more than "
                                            r"the 40 a trial file's number may have \(stimuli.reading.MAX_NUMBER_CHARS\)"):
        stimuli.load_trial("X1", folder)
    folder = _trial(tmp_path, X1.replace("min_gap: 0.01", "min_gap: 0." + "0" * 60 + "1"))
    with pytest.raises(StimulusError, match="a number of 63 characters"):
        stimuli.load_trial("X1", folder)


def _target(n: int) -> str:
    head = X1[: X1.index("target:")]
    return head + "target:\n  blocks:\n" + "".join(
        f"  - name: t{i}\n    p_WB: [{-1.9 + (i % 70) * 0.0508:.4f}, {-1.9 + (i // 70) * 0.0254:.4f}, 0.0127]\n" for i in range(n))


def test_a_trial_of_more_blocks_than_a_state_may_hold_is_refused_before_they_are_built(tmp_path):
    from stimuli.trial import MAX_BLOCKS

    with deadline(20), pytest.raises(StimulusError, match=f"X1-B blocks: {MAX_BLOCKS + 1} blocks in one state, more than "
                                                          f"the {MAX_BLOCKS} allowed \\(stimuli.trial.MAX_BLOCKS"):
        stimuli.load_trial("X1", _trial(tmp_path, _target(MAX_BLOCKS + 1)))
    colours = X1.replace("    count: 3\n", "    colours: [" + ", ".join(["red"] * (MAX_BLOCKS + 1)) + "]\n")
    with pytest.raises(StimulusError, match=f"X1-A scattered colours: {MAX_BLOCKS + 1} blocks in one state"):
        stimuli.load_trial("X1", _trial(tmp_path, colours))


@pytest.mark.slow  # YAML of 10,000 blocks: about 2.5 s to parse on a loaded machine (29 s to refuse before)
def test_a_10000_block_trial_is_refused_in_seconds(tmp_path):
    with deadline(20), pytest.raises(StimulusError, match="X1-B blocks: 10000 blocks in one state"):
        stimuli.load_trial("X1", _trial(tmp_path, _target(10_000)))


def test_the_paper_trials_are_far_inside_the_limits():
    from stimuli.trial import MAX_BLOCKS

    for trial in stimuli.load_paper():
        assert len(trial.target.blocks) <= 26 < MAX_BLOCKS
    assert os.path.getsize(stimuli.TRIAL_DIR / "12H.yaml") < 4000

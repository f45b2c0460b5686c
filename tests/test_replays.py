"""A run's 3-D replays record the plans the effort stage made (lgp.app.replays): sample
0 of each trial is planned once, not again for its replay, and the page is byte for
byte the one planning it again gives."""
from __future__ import annotations

import stimuli
from lgp import reproduce
from lgp.app import replays
from models.effort import plan_of_sample

ARGS = ["--trials", "1E", "10H", "--samples", "2", "--n-sims", "2", "--sigmas", "0.05", "--jobs", "1", "--n-boot", "10"]


def _pages(out):
    return {p.name: p.read_bytes() for p in sorted((out / "replays").iterdir())}


def test_a_fresh_run_records_each_replay_from_the_effort_stages_plan_of_sample_0(tmp_path, monkeypatch, capsys):
    def planned_again(item):
        raise AssertionError(f"{item[0].id}: sample 0 planned a second time for its replay")

    real = replays._replay_job
    monkeypatch.setattr(replays, "_replay_job", planned_again)
    out = tmp_path / "r"
    assert reproduce.main([*ARGS, "--out", str(out)]) == 0
    assert "[replays] 2 trials recorded from the effort stage's plans of sample 0" in capsys.readouterr().err
    for tid in ("1E", "10H"):
        trial = stimuli.load_trial(tid)
        page, library = replays.replay_page(plan_of_sample(trial, 0, 0), trial, 0)
        assert (out / "replays" / f"{tid}.html").read_text() == page, tid
    assert (out / "replays" / replays.REPLAY_LIBRARY).read_text() == library
    made = _pages(out)

    # The effort cached, the replays gone from the cache: the replay stage plans them (the
    # other path), to the same bytes.
    for f in (out / "cache").glob("replay-*.html"):
        f.unlink()
    monkeypatch.setattr(replays, "_replay_job", real)
    again = tmp_path / "again"
    (again / "cache").parent.mkdir(parents=True)
    __import__("shutil").copytree(out / "cache", again / "cache")
    assert reproduce.main([*ARGS, "--out", str(again)]) == 0
    assert "[replays] 2 trials planned (sample 0) and recorded" in capsys.readouterr().err
    assert _pages(again) == made

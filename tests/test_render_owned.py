"""The render command writes only where it can prove the files are its own
(stimuli.render.run.render_trials, the boundary every caller goes through): a
picture's name or renders.json holding a user's file, a picture edited since the run
wrote it, a folder of the user's files without a render record, are refused in one
line before anything is written; an interrupted run leaves the folder as it was.

The pictures here are stand-ins (`_render_chunk` replaced by one that writes each
picture's inputs as bytes): which files a run may replace does not depend on pixels."""
from __future__ import annotations

import hashlib
import json

import pytest

import stimuli
from lgp.owned import ForeignFiles
from stimuli.render import run
from stimuli.render.__main__ import main

SIZE = (80, 60)


@pytest.fixture
def renders(monkeypatch):
    """Counts of pictures each run rendered; pictures are written as their job's bytes."""
    calls = []

    def fake_chunk(jobs):
        for scene_file, png, camera in jobs:
            with open(png, "wb") as fh:
                fh.write(b"picture of " + hashlib.sha256(open(scene_file, "rb").read()).hexdigest().encode())
        calls.append(len(jobs))
        return [0.0] * len(jobs)

    monkeypatch.setattr(run, "_render_chunk", fake_chunk)
    return calls


def snapshot(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def render(out):
    return run.render_trials([stimuli.load_trial("1E")], out, 0, SIZE, jobs=1, log=lambda m: None)


def test_a_rerun_reuses_its_own_pictures_and_writes_nothing_else(tmp_path, renders):
    out = tmp_path / "pictures"
    record = render(out)
    assert sorted(snapshot(out)) == ["1E-A.png", "1E-B.png", "renders.json"] and renders == [2]
    assert {p["file"]: p["sha256"] for p in record["pictures"]} == \
        {name: hashlib.sha256(data).hexdigest() for name, data in snapshot(out).items() if name.endswith(".png")}
    assert render(out)["rendered"] == 0 and renders == [2]  # nothing rendered again
    assert not [p for p in out.iterdir() if p.name.startswith(".lgp-")]  # no staging folder left


def test_a_picture_edited_since_the_run_wrote_it_is_refused_and_left_as_it_was(tmp_path, renders):
    out = tmp_path / "pictures"
    render(out)
    (out / "1E-A.png").write_bytes(b"my retouched picture")
    before = snapshot(out)
    with pytest.raises(ForeignFiles, match=r"1E-A.png would replace what no render run wrote"):
        render(out)
    assert snapshot(out) == before and renders == [2]


def test_a_users_folder_is_refused_by_the_command_in_one_line_with_exit_2(tmp_path, renders, capsys):
    from lgp import cli

    out = tmp_path / "thesis"
    out.mkdir()
    (out / "1E-A.png").write_bytes(b"my own photograph of trial 1E")
    (out / "thesis.txt").write_text("chapter 1\n")
    before = snapshot(out)
    code = cli.run_cli(main, ["--out", str(out), "--trials", "1E", "--size", "96x64", "--jobs", "1"], prog=run.PROG)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "holds files no render run wrote (1E-A.png, thesis.txt) and no renders.json" in err
    assert snapshot(out) == before and renders == []


def test_a_renders_json_of_another_program_is_never_replaced(tmp_path, renders):
    out = tmp_path / "web"
    out.mkdir()
    (out / "renders.json").write_text(json.dumps({"pictures": "my render farm's queue"}))
    before = snapshot(out)
    with pytest.raises(ForeignFiles, match="renders.json there is not a render record"):
        render(out)
    assert snapshot(out) == before and renders == []


def test_an_interrupted_render_leaves_the_earlier_pictures_byte_identical(tmp_path, renders, monkeypatch):
    out = tmp_path / "pictures"
    render(out)
    before = snapshot(out)
    monkeypatch.setattr(run, "_code_version", lambda: "edited renderer")  # every picture is stale

    def interrupted(jobs):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "_render_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        render(out)
    assert snapshot(out) == before and sorted(p.name for p in out.iterdir()) == ["1E-A.png", "1E-B.png", "renders.json"]


def test_a_trial_rendered_for_one_set_is_copied_from_the_store_for_another(tmp_path, renders):
    # The render cache keeps a folder per set of trials (cache_folder); the store keeps
    # each picture by the hash of its inputs, so a run of {1E, 2E} after one of {1E}
    # renders 2E's two pictures only, and 1E's copies are byte for byte the first run's.
    store = tmp_path / "by-key"
    trials = [stimuli.load_trial(t) for t in ("1E", "2E")]
    first = run.render_trials(trials[:1], tmp_path / "one", 0, SIZE, jobs=1, log=lambda m: None, store=store)
    assert first["rendered"] == 2 and renders == [2]
    assert sorted(p.name for p in store.iterdir()) == sorted(f"{p['key']}.png" for p in first["pictures"])
    second = run.render_trials(trials, tmp_path / "two", 0, SIZE, jobs=1, log=lambda m: None, store=store)
    assert second["rendered"] == 2 and renders == [2, 2]  # 2E's pictures only
    for name in ("1E-A.png", "1E-B.png"):
        assert (tmp_path / "two" / name).read_bytes() == (tmp_path / "one" / name).read_bytes()
    assert len(list(store.iterdir())) == 4 and not [p for p in store.iterdir() if p.name.startswith(".")]
    # another size is another picture: rendered, not copied
    run.render_trials(trials[:1], tmp_path / "big", 0, (SIZE[0] * 2, SIZE[1] * 2), jobs=1, log=lambda m: None, store=store)
    assert renders == [2, 2, 2]

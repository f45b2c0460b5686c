"""What a user reads at the end of `python -m lgp.reproduce`: two lines (how long,
what was computed and what reused, where the page is), the file list only with
--verbose (it is in manifest.json); stage headers in words; --fall-rule read
case-insensitively with argparse's `argument --fall-rule:` prefix on refusal."""
import json
import re

import pytest

from lgp import cli, reproduce

SMALL = ["--trials", "1E", "9E", "--samples", "2", "--n-sims", "2", "--sigmas", "0.05", "--no-replays", "--jobs", "1"]
END = re.compile(r"^done in [0-9.]+ s \((\d+) results computed, (\d+) reused(?:: ([^;]+?(?:; [^;]+?)?))?\); open (.+index\.html)$")


def _run(argv, capsys):
    code = cli.run_cli(reproduce.main, argv, prog=reproduce.PROG)
    return code, capsys.readouterr()


@pytest.mark.slow
def test_a_run_ends_with_two_lines_and_a_rerun_says_everything_was_reused(tmp_path, capsys):
    out = tmp_path / "results"
    code, got = _run(["--out", str(out), *SMALL], capsys)
    assert code == 0, got.err
    lines = got.out.strip().splitlines()
    assert len(lines) == 2, got.out
    m = END.match(lines[0])
    # nothing of the results reused; the pictures of A and B may come from the renderer's own cache (stimuli.render)
    assert m and int(m.group(1)) > 0 and int(m.group(2)) <= 2 * 2, lines[0]
    assert m.group(4) == str(out / "index.html") and (out / "index.html").exists()
    if int(m.group(2)):  # reused: the pictures, from the render cache shared by every run (not this folder's)
        assert m.group(3).startswith(f"{m.group(2)} trial pictures from the render cache shared by every run, "), lines[0]
    files = json.loads((out / "manifest.json").read_text())["files"]
    assert lines[1] == f"the {len(files)} files written are listed in {out / 'manifest.json'} (--verbose prints them)"
    # the stage headers say what is counted: 1E's A is fixed (planned once), 9E's random
    assert "effort: 3 plans to make for 2 trial(s) (1 x 2 random layouts of A, and 1 trial(s) whose A has no random blocks, planned once)" in got.err
    assert "risk: 4 simulations of B (2 trial(s) x 1 sigma(s) x 2 noisy runs)" in got.err
    assert "hit" not in got.err and "miss" not in got.err  # no cache jargon
    # a run of some trials (as a --stimuli run): no figures, so no link to them; every #link has its target
    page = (out / "index.html").read_text()
    assert 'href="#figures"' not in page and 'id="figures"' not in page
    anchors = set(re.findall(r'href="#([^"]+)"', page))
    assert anchors and anchors <= set(re.findall(r'id="([^"]+)"', page)), anchors - set(re.findall(r'id="([^"]+)"', page))

    code, again = _run(["--out", str(out), *SMALL, "--verbose"], capsys)
    assert code == 0
    m = END.match(again.out.strip().splitlines()[-2])
    first = END.match(lines[0])
    assert m and int(m.group(1)) == 0 and int(m.group(2)) == int(first.group(1)) + int(first.group(2)), again.out
    assert f"from this folder's cache {out / 'cache'}" in m.group(3), again.out
    listed = [line.strip() for line in again.out.splitlines() if line.startswith("  ")]
    assert str(out / "index.html") in listed and len(listed) == len(files) + 1  # + manifest.json


def test_fall_rule_is_case_insensitive_and_refused_with_its_flag_named(tmp_path, capsys):
    args = reproduce.parse_args(["--out", str(tmp_path / "r"), "--fall-rule", "3D"])
    assert args.fall_rule == "3d"
    with pytest.raises(SystemExit) as e:
        reproduce.parse_args(["--out", str(tmp_path / "r"), "--fall-rule", "up"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("python -m lgp.reproduce: error: argument --fall-rule: unknown fall rule 'up'"), err

"""Outputs under faults (issue 27, items 9 and 11): every output goes through the
one atomic writer, so a full disk leaves no partial file and the error names the
file and says the disk is full; and no CSV cell from user text runs as a
spreadsheet formula."""
import errno
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.run import run_analysis
from analysis.simulate import simulate_participants
from lgp.atomic import DiskFull, spreadsheet_safe, write_csv_atomic
from lgp.cli import one_line

ROOT = Path(__file__).resolve().parents[1]
EVIL = ["=cmd|' /C calc'!A0", "+SUM(1+1)", "@SUM(A1)", "-2+3", "\t=1+1"]


@pytest.fixture
def sim(make_effort, make_risk):
    E, R = make_effort(), make_risk()
    return E, R, simulate_participants(E, R, (0.0, 1.0, 4.0), 0.075, 6, 1.0, np.random.default_rng(3),
                                       datasets=("time",))


def test_formula_cells_are_neutralised_and_numbers_kept():
    df = pd.DataFrame({"participant": EVIL + ["-1.5", "p7"], "z": [-1.0, 2, 3, 4, 5, 6, -7]})
    safe = spreadsheet_safe(df)
    assert safe["participant"].tolist()[:5] == ["'" + v for v in EVIL]
    assert safe["participant"].tolist()[5:] == ["-1.5", "p7"]  # a number is no formula
    assert safe["z"].equals(df["z"]) and df["participant"].tolist()[0] == EVIL[0]  # the input is untouched


def test_participant_ids_that_look_like_formulas_reach_no_csv_as_formulas(tmp_path, sim):
    E, R, responses = sim
    ids = sorted(responses["participant"].unique())
    responses = responses.assign(participant=responses["participant"].map(dict(zip(ids, EVIL + ["p6"]))))
    run_analysis(responses, E, R, tmp_path, seed=0, n_boot=20, jobs=1, figures=False)
    checked = 0
    for path in tmp_path.glob("*.csv"):
        for row in pd.read_csv(path, dtype=str, keep_default_na=False).itertuples(index=False):
            for cell in row:
                assert not (cell[:1] in "=+@\t\r" and cell), f"{path.name}: formula cell {cell!r}"
                assert cell != "-2+3", f"{path.name}: formula cell {cell!r}"
                checked += cell.startswith("'")
    assert checked >= 5 * 24  # every response row of the five ids in zscored.csv


_FULL_DISK = textwrap.dedent("""
    import os, subprocess, sys
    from pathlib import Path
    mnt = Path(sys.argv[1])
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(mnt)], check=True)
    import numpy as np
    from analysis.run import run_analysis
    from analysis.simulate import simulate_participants
    from lgp.cli import one_line
    sys.path.insert(0, sys.argv[2])
    from tests.conftest import synthetic_effort, synthetic_risk
    E, R = synthetic_effort(), synthetic_risk()
    sim = simulate_participants(E, R, (0.0, 1.0, 4.0), 0.075, 6, 1.0, np.random.default_rng(3), datasets=("time",))
    try:
        run_analysis(sim, E, R, mnt / "analysis", seed=0, n_boot=20, jobs=1)
        print("WROTE ALL")
    except OSError as e:
        print("ERROR", one_line(e))
    for p in sorted((mnt / "analysis").rglob("*")):
        print("FILE", p.name, p.stat().st_size)
""")


@pytest.mark.slow  # a subprocess run on a full disk
def test_a_full_disk_leaves_no_partial_output_and_names_the_file(tmp_path):
    """A real full disk: a 96 kB tmpfs in a private mount namespace (unshare -rm)."""
    if shutil.which("unshare") is None or subprocess.run(["unshare", "-rm", "true"]).returncode != 0:
        pytest.skip("no user and mount namespaces here (unshare -rm); the simulated ENOSPC test covers the writer")
    (tmp_path / "mnt").mkdir()
    script = tmp_path / "full.py"
    script.write_text(_FULL_DISK)
    r = subprocess.run(["unshare", "-rm", sys.executable, str(script), str(tmp_path / "mnt"), str(ROOT)],
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    lines = r.stdout.splitlines()
    error = [ln for ln in lines if ln.startswith("ERROR")]
    assert error and "WROTE ALL" not in r.stdout, r.stdout
    assert "analysis/" in error[0] and "No space left on device: the disk is full" in error[0], error[0]
    files = [ln.split() for ln in lines if ln.startswith("FILE")]
    assert files, r.stdout  # some outputs fitted ...
    for _, name, size in files:  # ... each whole: no empty file, no temporary left behind
        assert int(size) > 0 and not name.startswith("."), (name, size)


@pytest.mark.slow  # the analysis with its figures
def test_a_simulated_enospc_in_a_figure_leaves_nothing_and_names_the_figure(tmp_path, sim, monkeypatch):
    import matplotlib.figure

    E, R, responses = sim
    real = matplotlib.figure.Figure.savefig

    def full(self, fname, *a, **k):
        if "fig4" in str(fname) or "fig4" in Path(str(fname)).name:
            Path(fname).write_bytes(b"")  # what a full disk leaves: the file opened, nothing written
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, fname, *a, **k)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", full)
    with pytest.raises(DiskFull) as e:
        run_analysis(responses, E, R, tmp_path, seed=0, n_boot=20, jobs=1)
    assert "simulated_fig4_model_correlations.png: No space left on device: the disk is full" in one_line(e.value)
    assert not list(tmp_path.glob("*fig4*")) and not list(tmp_path.glob(".*"))


def test_write_csv_atomic_on_enospc_names_the_file(tmp_path, monkeypatch):
    def full(self, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(DiskFull, match="No space left on device: the disk is full"):
        write_csv_atomic(pd.DataFrame({"a": [1]}), tmp_path / "x.csv")
    assert list(tmp_path.iterdir()) == []

"""A cache entry is tied to its key and read within bounds:
an entry copied over another's passes its checksum but names another key, so it
is reported and recomputed, never used as the other trial's result; an entry
that is a symlink to /dev/zero, a FIFO or a file outside the cache is refused
before it is read."""
import os
import shutil

import pandas as pd
import pytest

from lgp.app.cache import Cache, entry_bytes


def _table(trial, value):
    return pd.DataFrame({"trial": [trial, trial], "sigma": [0.05, 0.1], "risk": [value, value / 2]})


def _two(tmp_path):
    cache = Cache(tmp_path / "cache")
    cache.put("risk", "aaaa1111", _table("1E", 0.2))
    cache.put("risk", "bbbb2222", _table("7H", 0.9))
    return cache


def test_an_entry_copied_over_another_is_damaged_not_used(tmp_path, capsys):
    cache = _two(tmp_path)
    shutil.copy(cache.path("risk", "bbbb2222"), cache.path("risk", "aaaa1111"))  # 7H's over 1E's
    fresh = Cache(cache.root)
    assert fresh.get("risk", "aaaa1111") is None
    assert fresh.count("recomputed") == 1
    err = capsys.readouterr().err
    assert "it holds the risk entry bbbb2222 of trial 7H, not risk aaaa1111" in err, err
    assert fresh.get("risk", "bbbb2222")["trial"].tolist() == ["7H", "7H"]  # the original is sound


def test_an_entry_renamed_to_another_kind_is_damaged(tmp_path):
    cache = _two(tmp_path)
    os.replace(cache.path("risk", "aaaa1111"), cache.path("effort", "aaaa1111"))
    assert Cache(cache.root).get("effort", "aaaa1111") is None


def test_an_entry_whose_rows_are_of_another_trial_than_its_header_is_damaged(tmp_path):
    cache = _two(tmp_path)
    data = entry_bytes(_table("1E", 0.2), "risk", "aaaa1111").replace(b"trial=1E", b"trial=7H")
    cache.path("risk", "aaaa1111").write_bytes(data)
    assert Cache(cache.root).get("risk", "aaaa1111") is None


def test_an_entry_of_the_old_format_is_recomputed(tmp_path, capsys):
    cache = _two(tmp_path)
    body = _table("1E", 0.2).to_csv(index=False).encode()
    import hashlib

    cache.path("risk", "aaaa1111").write_bytes(b"# lgp.cache v1 rows=2 sha256=%s\n" % hashlib.sha256(body).hexdigest().encode() + body)
    assert Cache(cache.root).get("risk", "aaaa1111") is None
    assert "older version, without its key" in capsys.readouterr().err


@pytest.mark.parametrize("make", ["dev-zero", "fifo", "outside", "dangling"])
def test_a_special_entry_is_refused_before_it_is_read_and_then_replaced(tmp_path, capsys, make):
    cache = _two(tmp_path)
    path = cache.path("risk", "aaaa1111")
    path.unlink()
    outside = tmp_path / "elsewhere.csv"
    outside.write_bytes(entry_bytes(_table("1E", 0.2), "risk", "aaaa1111"))
    {"dev-zero": lambda: path.symlink_to("/dev/zero"), "fifo": lambda: os.mkfifo(path),
     "outside": lambda: path.symlink_to(outside), "dangling": lambda: path.symlink_to(tmp_path / "gone")}[make]()
    fresh = Cache(cache.root)
    assert fresh.get("risk", "aaaa1111") is None and fresh.count("recomputed") == 1
    assert "damaged entry" in capsys.readouterr().err
    fresh.put("risk", "aaaa1111", _table("1E", 0.2))  # the rewrite replaces the link or FIFO itself
    assert path.is_file() and not path.is_symlink()
    assert Cache(cache.root).get("risk", "aaaa1111")["risk"].tolist() == [0.2, 0.1]
    assert outside.exists()


@pytest.mark.slow
def test_a_run_with_one_trials_risk_entry_copied_over_anothers_recomputes_it(tmp_path, capsys):
    """The issue's probe end to end: 7H's risk entry copied over 4H's; the rerun
    reports it, recomputes 4H and writes the first run's risk.csv (it wrote 7H twice).
    Both runs in this process (a run's imports paid once; the cache is on disk)."""
    from lgp import cli, reproduce
    from lgp.app.cache import read_entry

    run = ["--trials", "7H", "4H", "--samples", "2", "--n-sims", "10",
           "--sigmas", "0.05", "0.1", "--jobs", "1", "--no-replays", "--verbose", "--out", str(tmp_path / "out")]
    assert cli.run_cli(reproduce.main, run, prog=reproduce.PROG) == 0, capsys.readouterr().err[-2000:]
    capsys.readouterr()
    before = (tmp_path / "out" / "risk.csv").read_bytes()
    entries = {read_entry(p)["trial"].iloc[0]: p for p in (tmp_path / "out" / "cache").glob("riskruns-*.csv")}
    shutil.copy(entries["7H"], entries["4H"])
    code = cli.run_cli(reproduce.main, run, prog=reproduce.PROG)
    err = capsys.readouterr().err
    assert code == 0, err[-2000:]
    assert "of trial 7H, not riskruns" in err and "riskruns 1 hit, 0 miss, 1 recomputed" in err, err
    assert (tmp_path / "out" / "risk.csv").read_bytes() == before

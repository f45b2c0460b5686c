"""A cache entry is checked for what it holds, not only for its checksum:
an entry re-signed with wrong contents (``effort: abc``, which would raise a TypeError; ``-1e308``,
which would be published as ``-3.3e+307,inf``) is reported and recomputed; a damaged
``compute_times.json`` never stops a rerun; and the end of a run counts a
recomputed entry as computed."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lgp.app.cache import ENTRY_SCHEMAS, Cache, DamagedEntry, check_entry
from lgp.app.manifest import TimedCache
from lgp.reproduce import end_of_run


def _effort(**change) -> pd.DataFrame:
    df = pd.DataFrame({"trial": ["1E"] * 3, "sample": [0, 1, 2], "effort": [0.5, 0.7, 0.6], "n_actions": [4, 4, 5],
                       "solve_time": [1.0, 1.1, 0.9], "solver": "snopt", "status": "kSolutionFound"})
    for column, value in change.items():
        df[column] = df[column].astype(object)
        df.loc[1, column] = value
    return df


def _runs(n_sims=2, **change) -> pd.DataFrame:
    df = pd.DataFrame({"trial": "7H", "sigma": np.repeat([0.05, 0.1], n_sims), "run": np.tile(np.arange(n_sims), 2),
                       "fell": [True, False] * n_sims, "engine": "mujoco", "fall_rule": "horizontal",
                       "fall_threshold": 0.25, "noise_rule": "lift"})
    for column, value in change.items():
        df[column] = df[column].astype(object)
        df.loc[1, column] = value
    return df


def _read_back(tmp_path, kind, df, rows=None):
    """`df` written as a sound, correctly signed entry, read by a fresh Cache."""
    root = tmp_path / "cache"
    Cache(root).put(kind, "k", df)
    fresh = Cache(root)
    return fresh.get(kind, "k", rows=rows), fresh


@pytest.mark.parametrize("column, value, why", [
    ("effort", "abc", "effort 'abc' is not a finite number in [0, 1e+06]"),
    ("effort", -1e308, "effort '-1e+308' is not a finite number"),
    ("effort", float("inf"), "effort 'inf' is not a finite number"),
    ("effort", float("nan"), "effort 'nan' is not a finite number"),
    ("sample", 1.5, "sample '1.5' is not a finite whole number >= 0"),
    ("trial", "1E 2", "trial '1E 2' is not a trial id"),
])
def test_a_re_signed_effort_entry_with_wrong_values_is_recomputed(tmp_path, capsys, column, value, why):
    got, cache = _read_back(tmp_path, "effort", _effort(**{column: value}))
    assert got is None and cache.recomputed == 1 and cache.computed == 1 and cache.hits == 0
    err = capsys.readouterr().err
    assert "lgp.cache: damaged entry" in err and why in err and "recomputing it" in err and err.count("\n") == 1, err


@pytest.mark.parametrize("change, rows, why", [
    ({"fell": "maybe"}, None, "fell 'maybe' is not True or False"),
    ({"sigma": 2.0}, None, "sigma '2.0' is not a finite number in [0, 1]"),
    ({}, 6, "4 rows, this run expects 6"),
])
def test_a_re_signed_risk_entry_with_wrong_values_or_rows_is_recomputed(tmp_path, capsys, change, rows, why):
    got, cache = _read_back(tmp_path, "riskruns", _runs(**change), rows=rows)
    assert got is None and cache.recomputed == 1
    assert why in capsys.readouterr().err


def test_a_sound_entry_reads_back_with_its_types():
    df = check_entry("riskruns", _runs().astype({"fell": str}), rows=4)
    assert df["fell"].dtype == bool and df["fell"].tolist() == [True, False, True, False]
    assert df["run"].dtype.kind == "i" and df["sigma"].dtype == float
    eff = check_entry("effort", _effort())
    assert eff["effort"].tolist() == [0.5, 0.7, 0.6]
    with pytest.raises(DamagedEntry, match="column.s. effort missing"):
        check_entry("effort", _effort().drop(columns="effort"))
    assert check_entry("no-schema-kind", _effort(effort="abc")) is not None  # kinds without a schema pass
    assert set(ENTRY_SCHEMAS) >= {"effort", "riskruns", "stable"}


def test_a_sound_entry_is_still_a_hit(tmp_path):
    got, cache = _read_back(tmp_path, "effort", _effort())
    assert got is not None and cache.hits == 1 and cache.recomputed == 0
    pd.testing.assert_frame_equal(got[["sample", "effort"]], _effort()[["sample", "effort"]], check_dtype=False)


@pytest.mark.parametrize("text", ['{"x": null}', '{"x": "abc", "y": 1.5}', '[1, 2]', '{"x": -1, "y": 1e999}', "null"])
def test_a_damaged_compute_times_file_never_stops_a_rerun(tmp_path, text):
    root = tmp_path / "cache"
    root.mkdir()
    (root / "compute_times.json").write_text(text)
    cache = TimedCache(root)
    times = cache.load_times()
    assert all(isinstance(v, float) and np.isfinite(v) and v >= 0 for v in times.values())
    assert times == ({"y": 1.5} if '"y": 1.5' in text else {})
    with cache.stage():  # a stage that writes an entry records its time beside the sound ones
        cache.put("effort", "k", _effort())
    again = json.loads((root / "compute_times.json").read_text())
    assert "effort-k.csv" in again and all(v is not None for v in again.values())
    assert cache.compute_time()[0] >= 0


def test_the_end_of_a_run_counts_a_recomputed_entry_as_computed(tmp_path, capsys):
    """It said "0 results computed" after recomputing a damaged entry."""
    root = tmp_path / "cache"
    Cache(root).put("effort", "k", _effort(effort="abc"))
    cache = Cache(root)
    assert cache.get("effort", "k") is None
    capsys.readouterr()
    line = end_of_run(3.0, cache, Path("out"), 5).splitlines()[0]
    assert line == "done in 3.0 s (1 results computed, 0 reused); open out/index.html"

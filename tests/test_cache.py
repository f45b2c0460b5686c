"""Cached results are keyed by their inputs and written atomically."""
import pandas as pd
import pytest

from lgp.cache import Cache, code_version, input_key, write_csv_atomic


def test_second_call_reuses_the_cached_table(tmp_path):
    cache, calls = Cache(tmp_path), []

    def compute():
        calls.append(1)
        return pd.DataFrame({"trial": ["7H"], "effort": [1.25]})

    a = cache.get_or_compute("effort", input_key(trial="7H", samples=3), compute)
    b = cache.get_or_compute("effort", input_key(trial="7H", samples=3), compute)
    assert len(calls) == 1 and (cache.hits, cache.misses) == (1, 1)
    pd.testing.assert_frame_equal(a, b)


def test_key_changes_with_any_input():
    assert input_key(trial="7H", samples=3) != input_key(trial="7H", samples=4)
    assert input_key(trial="7H", samples=3) == input_key(samples=3, trial="7H")


def test_interrupted_write_leaves_no_file(tmp_path):
    class Boom(pd.DataFrame):
        def to_csv(self, *a, **k):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_csv_atomic(Boom({"x": [1]}), tmp_path / "r.csv")
    assert list(tmp_path.iterdir()) == []


def test_code_version_tracks_source_files():
    assert code_version("lgp/cache.py") != code_version("lgp/scene.py")
    assert len(code_version("lgp/*.py")) == 16

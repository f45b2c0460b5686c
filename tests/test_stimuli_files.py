"""Trial files from strangers: every field gets a typed, named StimulusError, YAML
anchors/aliases and oversized files are refused, and a scatter region that cannot
hold its blocks fails at once with the reason."""
import re

import numpy as np
import pytest

import stimuli
from lgp.paper import BLOCK_SIZE as d
from stimuli import StartState, ScatterRegion, StimulusError

BASE = (stimuli.TRIAL_DIR / "1E.yaml").read_text()


def _load(tmp_path, text, name="1E.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return stimuli.load_file(path)


@pytest.mark.parametrize("old, new, message", [
    ("pair: 1", "pair: thirteen", "1E pair: expected a whole number, got 'thirteen'"),
    ("count: 3", "count: three", "1E-A scattered count: expected a whole number, got 'three'"),
    ("count: 3", "count: 2.5", "1E-A scattered count: expected a whole number, got 2.5"),
    ("count: 3", "count: -1", "1E-A scattered count: must be >= 0, got -1"),
    ("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, 0.0, 0.0127]\n    yaw: left", "1E-B block b1 yaw: expected a number, got 'left'"),
    ("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, zero, 0.0127]", "1E-B block b1 p_WB: expected a number, got 'zero'"),
    ("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, 0.0]", "1E-B block b1 p_WB: expected 3 numbers"),
    ("min_gap: 0.01", "min_gap: wide", "1E-A scattered min_gap: expected a number, got 'wide'"),
    ("x: [0.2, 0.55]", "x: 0.2", "1E-A scattered region x: expected \\[min, max\\], got 0.2"),
    ("x: [0.2, 0.55]", "x: [0.55, 0.2]", "must be finite ranges \\[min, max\\]"),
    ("build_site: [0.35, 0.0]", "build_site: [here, 0.0]", "1E build_site: expected a number, got 'here'"),
])
def test_every_bad_field_raises_a_named_stimulus_error(tmp_path, old, new, message):
    assert old in BASE
    with pytest.raises(StimulusError, match=message):
        _load(tmp_path, BASE.replace(old, new, 1))


def test_numbers_written_without_a_dot_still_read_as_numbers(tmp_path):
    # YAML 1.1 reads 1e-2 as text; the loader takes text that is a number
    trial = _load(tmp_path, BASE.replace("min_gap: 0.01", "min_gap: 1e-2"))
    assert trial.initial.min_gap == 0.01


def test_yaml_aliases_are_refused_before_they_expand(tmp_path):
    bomb = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{chr(98 + k)}: &{chr(98 + k)} [{', '.join(['*' + chr(97 + k)] * 10)}]\n" for k in range(8))
    import tracemalloc

    tracemalloc.start()  # expanded, the bomb holds 10^9 references: refused first, it costs a few kB
    try:
        with pytest.raises(StimulusError, match="line 1: YAML anchors and aliases"):
            _load(tmp_path, bomb)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20e6, f"{peak / 1e6:.0f} MB"
    with pytest.raises(StimulusError, match="anchors and aliases"):
        _load(tmp_path, BASE.replace("x: [0.2, 0.55]", "x: &span [0.2, 0.55]"))


def test_files_over_the_size_limit_are_refused(tmp_path):
    big = BASE + "#" * (stimuli.MAX_TRIAL_BYTES + 1) + "\n"
    with pytest.raises(StimulusError, match=f"more than the {stimuli.MAX_TRIAL_BYTES} allowed"):
        _load(tmp_path, big)


def test_a_file_that_is_not_a_mapping_is_refused(tmp_path):
    with pytest.raises(StimulusError, match="a trial file is a mapping"):
        _load(tmp_path, "- just\n- a list\n")


def _scatter(n, x, y, r_S=None, min_gap=0.01):
    return StartState("T-A", (), (), tuple((f"s{i}", "natural") for i in range(n)), ScatterRegion(x, y, r_S), min_gap=min_gap, clearance=0.0)


def test_a_region_too_small_for_its_blocks_fails_at_once_with_the_areas():
    start = _scatter(100, (0.3, 0.4), (0.0, 0.1))
    class NoDraws:  # "at once": refused before a single position is drawn
        def __getattr__(self, name):
            raise AssertionError(f"drew from the generator ({name}) before refusing")

    with pytest.raises(StimulusError, match=r"cannot scatter 100 blocks .* need at least .* m\^2 .* at most .* m\^2 \(too small\)"):
        start.sample(NoDraws())


def test_the_area_bound_never_refuses_a_region_that_can_hold_its_blocks():
    # A square grid at pitch d + gap fits k x k blocks in a region of side (k - 1)(d + gap):
    # the bound must let it through (it is a necessary condition, not a guess).
    for k, gap in [(3, 0.01), (6, 0.0), (10, 0.002)]:
        side = (k - 1) * (d + gap)
        _scatter(k * k, (0.0, side), (0.0, side), min_gap=gap).check_room()


def test_a_huge_region_is_refused_at_once():
    with pytest.raises(StimulusError, match="bounds beyond 1000 m"):
        _scatter(3, (-1e300, 1e300), (-1e300, 1e300)).sample(np.random.default_rng(0))


def test_scattering_500_blocks_obeys_the_gap():
    start = _scatter(500, (-1.0, 1.0), (-1.0, 1.0))
    scene = start.sample(np.random.default_rng(1))  # no time bound here: the machines are shared
    from lgp.scene import horizontal_penetration, near_pairs
    from lgp.scene import Block

    grown = [Block(b.name, b.p_WB, b.yaw, size=np.full(3, d + 0.01)) for b in scene.blocks]
    assert not any(horizontal_penetration(grown[i], scene.blocks[j]) > 1e-12 for i, j in near_pairs(grown, scene.blocks) if i != j)


def test_the_spatial_hash_draws_the_layouts_the_pairwise_scatter_drew():
    # Same Generator, same layout: the hash only skips blocks too far to matter.
    trial = stimuli.load_trial("7E")
    rng = np.random.default_rng(5)
    scene = trial.sample_initial(rng)
    reference = _pairwise_scatter(trial.initial, np.random.default_rng(5))
    np.testing.assert_array_equal(scene.positions[-len(reference):], np.array([b.p_WB for b in reference]))


def _pairwise_scatter(start, rng):
    """The sampler as it was before the spatial hash (reference)."""
    from lgp.scene import Block, horizontal_penetration

    obstacles = [*start.blocks, *start.fixed]
    for _ in range(50):
        placed = []
        for name, colour in start.scattered:
            for _ in range(2000):
                p = np.array([rng.uniform(*start.region.x), rng.uniform(*start.region.y), d / 2])
                yaw = rng.uniform(0.0, np.pi / 2)
                if not start.region.contains(p, start.build_site):
                    continue
                cand_gap = Block(name, p, yaw, colour, size=np.full(3, d + 2 * start.min_gap))
                cand_clear = Block(name, p, yaw, colour, size=np.full(3, d + 2 * start.clearance))
                if any(horizontal_penetration(cand_gap, o) > 0 for o in placed):
                    continue
                if any(horizontal_penetration(cand_clear, o) > 0 for o in (*obstacles, *start.keep_clear)):
                    continue
                placed.append(Block(name, p, yaw, colour))
                break
            else:
                break
        if len(placed) == len(start.scattered):
            return placed
    raise AssertionError("reference sampler failed")


@pytest.mark.parametrize("old, new, problem", [
    # the case: a colon inside a value ("mapping values are not allowed")
    ("dimension: ", "dimension: a: ", "mapping values are not allowed"),
    ("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, 0.0, 0.0127", "expected ',' or ']'"),
])
def test_a_yaml_error_keeps_its_line_and_column_in_the_one_line_a_cli_prints(tmp_path, old, new, problem):
    from lgp.cli import one_line

    assert old in BASE
    text = BASE.replace(old, new, 1)
    with pytest.raises(StimulusError) as info:
        _load(tmp_path, text)
    line = one_line(info.value)
    assert "\n" not in str(info.value) and "more line(s)" not in line
    m = re.search(r"not valid YAML at line (\d+), column (\d+): (.*)", line)
    assert m and problem in m.group(3), line
    # the position names the line that was broken (the first line that differs from BASE, or after it)
    first_changed = next(k for k, (a, b) in enumerate(zip(BASE.splitlines(), text.splitlines())) if a != b) + 1
    assert first_changed <= int(m.group(1)) <= first_changed + 1, (line, first_changed)
    assert int(m.group(2)) >= 1

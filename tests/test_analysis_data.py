"""Human-data format, exclusions, z-scoring and trial-mean bootstrap (analysis.data)."""
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis import (TRIAL_IDS, HumanDataError, bootstrap_trial_means,
                      exclude_constant_participants, load_human_data, resample_trial_means,
                      trial_means, validate_human_data, zscore_responses)

HEADER = "dataset,participant,trial,response"


def valid_lines():
    """Two participants of the difficulty dataset: p1 on CSV lines 2-25, p2 on 26-49."""
    lines = [HEADER]
    for participant, base in (("p1", 10.0), ("p2", 40.0)):
        lines += [f"difficulty,{participant},{t},{base + k * 1.5}" for k, t in enumerate(TRIAL_IDS)]
    return lines


def write(tmp_path, lines, name="responses.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def replace_field(lines, line_number, column, value):
    """Copy of `lines` with one field of CSV line `line_number` (1-based) replaced."""
    lines = list(lines)
    fields = lines[line_number - 1].split(",")
    fields[HEADER.split(",").index(column)] = value
    lines[line_number - 1] = ",".join(fields)
    return lines


# ---- the CSV format -------------------------------------------------------------

def test_valid_csv_loads_every_row_with_its_line(tmp_path):
    table = load_human_data(write(tmp_path, valid_lines()))
    assert len(table) == 48
    assert table["line"].tolist() == list(range(2, 50))
    assert table.loc[table["line"] == 27, ["participant", "trial", "response"]].values.tolist() == \
        [["p2", "1H", 41.5]]


def test_bad_csv_names_row_for_unknown_trial(tmp_path):
    lines = replace_field(valid_lines(), 5, "trial", "13E")
    with pytest.raises(HumanDataError, match=r"line 5: unknown trial id '13E'") as err:
        load_human_data(write(tmp_path, lines))
    assert err.value.line == 5


def test_bad_csv_names_participant_and_trials_for_missing_trials(tmp_path):
    lines = valid_lines()
    # p2's 4H is line 26 + 7 = 33 and 7E is line 26 + 12 = 38.
    assert lines[32].endswith(",p2,4H,50.5") and lines[37].startswith("difficulty,p2,7E,")
    del lines[37], lines[32]
    with pytest.raises(HumanDataError) as err:
        load_human_data(write(tmp_path, lines))
    message = str(err.value)
    assert "participant 'p2'" in message and "missing trial(s) 4H, 7E" in message
    assert err.value.line == 26 and "line 26" in message
    assert "p1" not in message


def test_bad_csv_names_row_for_non_numeric_response(tmp_path):
    lines = replace_field(valid_lines(), 10, "response", "about 5")
    with pytest.raises(HumanDataError, match=r"line 10: non-numeric response 'about 5'") as err:
        load_human_data(write(tmp_path, lines))
    assert err.value.line == 10


def test_bad_csv_names_row_for_empty_response(tmp_path):
    lines = replace_field(valid_lines(), 11, "response", "")
    with pytest.raises(HumanDataError, match=r"line 11: empty response"):
        load_human_data(write(tmp_path, lines))


@pytest.mark.parametrize("value", ["nan", "inf", "-Infinity"])
def test_bad_csv_names_row_for_non_finite_response(tmp_path, value):
    lines = replace_field(valid_lines(), 30, "response", value)
    with pytest.raises(HumanDataError, match=rf"line 30: non-finite response '{value}'") as err:
        load_human_data(write(tmp_path, lines))
    assert err.value.line == 30


def test_bad_csv_names_both_rows_for_duplicate_response(tmp_path):
    lines = valid_lines() + ["difficulty,p1,3E,99"]  # line 50 repeats p1's 3E (line 6)
    with pytest.raises(HumanDataError) as err:
        load_human_data(write(tmp_path, lines))
    assert err.value.line == 50
    assert "line 50: duplicate response of participant 'p1'" in str(err.value)
    assert "trial 3E (first given on line 6)" in str(err.value)


def test_bad_csv_names_row_for_unknown_dataset(tmp_path):
    lines = replace_field(valid_lines(), 3, "dataset", "difficulty_v2")
    with pytest.raises(HumanDataError, match=r"line 3: unknown dataset 'difficulty_v2'") as err:
        load_human_data(write(tmp_path, lines))
    assert err.value.line == 3


def test_bad_csv_names_missing_columns(tmp_path):
    lines = [",".join(line.split(",")[:3]) for line in valid_lines()]  # drop `response`
    with pytest.raises(HumanDataError, match=r"line 1 \(header\): missing column\(s\) response"):
        load_human_data(write(tmp_path, lines))


def test_bad_csv_line_numbers_count_blank_lines(tmp_path):
    lines = replace_field(valid_lines(), 10, "trial", "X")
    lines.insert(3, "")  # a blank line 4 pushes the bad row to line 11
    with pytest.raises(HumanDataError, match=r"line 11: unknown trial id 'X'"):
        load_human_data(write(tmp_path, lines))


def test_simulated_dataset_is_refused_as_human_data(tmp_path):
    lines = [line.replace("difficulty,", "simulated-difficulty,") for line in valid_lines()]
    with pytest.raises(HumanDataError, match="simulated participants are not human data"):
        load_human_data(write(tmp_path, lines))
    assert len(load_human_data(write(tmp_path, lines), allow_simulated=True)) == 48


def test_dataframe_errors_name_the_line_of_the_row_in_a_written_csv():
    table = pd.read_csv(pd.io.common.StringIO("\n".join(valid_lines())))
    table.loc[4, "trial"] = "0E"  # row 4 is CSV line 6
    with pytest.raises(HumanDataError, match=r"line 6: unknown trial id '0E'"):
        validate_human_data(table)


# ---- exclusions and z-scores ------------------------------------------------------

def responses(rows):
    """Tidy responses from {(dataset, participant): 24 values in TRIAL_IDS order}."""
    return pd.DataFrame([(d, p, t, float(v)) for (d, p), values in rows.items()
                         for t, v in zip(TRIAL_IDS, values)],
                        columns=["dataset", "participant", "trial", "response"])


def test_zscore_matches_hand_computation():
    # Responses 0, 1, ..., 23: mean 11.5, population variance (n^2 - 1)/12 = 575/12,
    # sample variance n(n + 1)/12 = 50.
    table = responses({("time", "a"): range(24)})
    z_pop = zscore_responses(table).set_index("trial")["z"]
    assert z_pop["1E"] == pytest.approx(-11.5 / math.sqrt(575 / 12), rel=1e-12)
    assert z_pop["12H"] == pytest.approx(11.5 / math.sqrt(575 / 12), rel=1e-12)
    assert z_pop["5H"] == pytest.approx((9 - 11.5) / math.sqrt(575 / 12), rel=1e-12)
    z_sample = zscore_responses(table, ddof=1).set_index("trial")["z"]
    assert z_sample["1E"] == pytest.approx(-11.5 / math.sqrt(50), rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(-1000, 1000), min_size=24, max_size=24).filter(lambda v: len(set(v)) > 1))
def test_each_participants_zscores_have_mean_zero_and_unit_root_mean_square(values):
    z = zscore_responses(responses({("difficulty", "a"): values}))["z"].to_numpy()
    assert abs(z.mean()) < 1e-9
    assert np.sqrt(np.mean(z ** 2)) == pytest.approx(1.0, rel=1e-9)


def test_zscore_removes_each_participants_scale_and_offset():
    base = np.random.default_rng(0).normal(size=24)
    table = responses({("time", "a"): base, ("time", "b"): 7 + 3 * base})
    z = zscore_responses(table).pivot(index="trial", columns="participant", values="z")
    np.testing.assert_allclose(z["a"], z["b"], atol=1e-12)


def test_zscore_is_within_dataset_for_a_shared_participant_id():
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=24), 100 + 20 * rng.normal(size=24)
    table = responses({("time", "p7"): x, ("build", "p7"): y})
    z = zscore_responses(table)
    np.testing.assert_allclose(z.loc[z["dataset"] == "time", "z"], (x - x.mean()) / x.std(), atol=1e-12)
    np.testing.assert_allclose(z.loc[z["dataset"] == "build", "z"], (y - y.mean()) / y.std(), atol=1e-12)


def test_participant_with_identical_responses_is_dropped_and_reported():
    rng = np.random.default_rng(2)
    table = responses({("difficulty", "ok1"): rng.normal(size=24), ("difficulty", "flat"): [0.1] * 24,
                       ("time", "ok2"): rng.normal(size=24), ("time", "flat"): rng.normal(size=24)})
    kept, excluded = exclude_constant_participants(table)
    assert excluded[["dataset", "participant", "n_trials", "response"]].values.tolist() == \
        [["difficulty", "flat", 24, 0.1]]
    assert sorted(set(zip(kept["dataset"], kept["participant"]))) == \
        [("difficulty", "ok1"), ("time", "flat"), ("time", "ok2")]
    with pytest.raises(ValueError, match="'flat' in dataset 'difficulty'"):
        zscore_responses(table)


def test_trial_mean_is_mean_of_participant_zscores():
    rng = np.random.default_rng(3)
    a, b, c = rng.normal(size=(3, 24))
    means = trial_means(zscore_responses(responses({("time", "a"): a, ("time", "b"): b,
                                                    ("time", "c"): c})))
    z = [(v - v.mean()) / v.std() for v in (a, b, c)]
    np.testing.assert_allclose(means["mean_z"], (z[0] + z[1] + z[2]) / 3, atol=1e-12)
    assert means["trial"].tolist() == list(TRIAL_IDS)
    assert (means["n_participants"] == 3).all()


# ---- participant bootstrap of trial means --------------------------------------------

def test_bootstrap_trial_means_follow_the_documented_resampling():
    rng = np.random.default_rng(4)
    data = {("time", f"t{k}"): rng.normal(size=24) for k in range(7)}
    data |= {("difficulty", f"d{k}"): rng.normal(size=24) for k in range(5)}
    z = zscore_responses(responses(data))
    got = bootstrap_trial_means(z, 200, np.random.default_rng(11))
    # Independent re-derivation: datasets in the paper's order (difficulty before
    # time), rng.integers(0, n, (n_boot, n)) each, mean of the drawn participants.
    check = np.random.default_rng(11)
    for dataset, names in (("difficulty", [f"d{k}" for k in range(5)]),
                           ("time", [f"t{k}" for k in range(7)])):
        Z = np.array([(v - v.mean()) / v.std() for v in (data[(dataset, n)] for n in sorted(names))])
        idx = check.integers(0, len(names), size=(200, len(names)))
        boot = np.array([np.mean([Z[i] for i in draw], axis=0) for draw in idx])
        rows = got[got["dataset"] == dataset]
        np.testing.assert_allclose(rows["ci_low"], np.percentile(boot, 2.5, axis=0), atol=1e-12)
        np.testing.assert_allclose(rows["ci_high"], np.percentile(boot, 97.5, axis=0), atol=1e-12)
        np.testing.assert_allclose(rows["mean_z"], Z.mean(axis=0), atol=1e-12)


def test_bootstrap_is_reproducible_for_a_seed_and_differs_across_seeds():
    rng = np.random.default_rng(5)
    z = zscore_responses(responses({("build", f"b{k}"): rng.normal(size=24) for k in range(6)}))
    one = resample_trial_means(z, 50, np.random.default_rng(7))["build"]
    two = resample_trial_means(z, 50, np.random.default_rng(7))["build"]
    other = resample_trial_means(z, 50, np.random.default_rng(8))["build"]
    np.testing.assert_array_equal(one, two)
    assert not np.allclose(one, other)


def test_revalidating_a_loaded_table_keeps_its_csv_lines(tmp_path):
    lines = valid_lines()
    lines.insert(2, "")  # a blank line 3: p1's 1H is on line 4
    table = load_human_data(write(tmp_path, lines))
    again = validate_human_data(table)
    assert again["line"].tolist() == table["line"].tolist()
    assert again.loc[again["trial"] == "1H", "line"].tolist()[0] == 4

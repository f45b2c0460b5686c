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


# ---- edge cases of real files -----------------------------------

@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-32", "utf-8-sig"])
def test_a_file_with_a_byte_order_mark_is_read_in_its_encoding(tmp_path, encoding):
    text = "\n".join(valid_lines()) + "\n"
    data = text.encode(encoding)
    if encoding == "utf-16-be":
        data = b"\xfe\xff" + data  # Python writes no BOM for the explicit-endian codec
    path = tmp_path / "responses.csv"
    path.write_bytes(data)
    assert load_human_data(path).equals(load_human_data(write(tmp_path, valid_lines(), "plain.csv")))


def test_a_latin_1_file_names_the_file_line_and_expected_encoding(tmp_path):
    lines = replace_field(valid_lines(), 7, "participant", "Zoë")
    path = tmp_path / "latin1.csv"
    path.write_bytes(("\n".join(lines) + "\n").encode("latin-1"))
    with pytest.raises(HumanDataError, match=r"latin1\.csv: line 7: not UTF-8 text .*save the file as UTF-8") as err:
        load_human_data(path)
    assert err.value.line == 7


def test_a_utf_16_file_without_byte_order_mark_is_refused_by_name(tmp_path):
    path = tmp_path / "bare16.csv"
    path.write_bytes(("\n".join(valid_lines()) + "\n").encode("utf-16-le"))
    with pytest.raises(HumanDataError, match=r"bare16\.csv: .*not UTF-8 text"):
        load_human_data(path)


def test_a_header_only_file_is_refused_up_front(tmp_path):
    with pytest.raises(HumanDataError, match=r"line 1 \(header\): no responses after the header"):
        load_human_data(write(tmp_path, [HEADER]))


@pytest.mark.parametrize("value", ["1_000", "1_0.5", "١٢", "０.５"])
def test_python_only_number_syntax_is_not_a_csv_number(tmp_path, value):
    lines = replace_field(valid_lines(), 9, "response", value)
    with pytest.raises(HumanDataError, match=rf"line 9: non-numeric response '{value}'"):
        load_human_data(write(tmp_path, lines))


def test_responses_too_large_to_zscore_are_refused_naming_the_participant(tmp_path):
    """1e308 is finite, but its square overflows: the SD is inf and every z-score 0
    or NaN. Validation names the participant; so does zscore_responses on a table
    that bypassed it."""
    lines = replace_field(valid_lines(), 30, "response", "1e308")
    with pytest.raises(HumanDataError, match=r"line 26: participant 'p2' .*too large to z-score") as err:
        load_human_data(write(tmp_path, lines))
    assert "p1" not in str(err.value)
    table = load_human_data(write(tmp_path, valid_lines()))
    table.loc[table["line"] == 30, "response"] = 1e308
    with pytest.raises(HumanDataError, match=r"participant 'p2' in dataset 'difficulty': z-scores are not finite"):
        zscore_responses(table)


def _reference_validation(table: pd.DataFrame, allowed) -> list[str]:
    """The row-by-row validation the vectorised one replaced (same rules, same
    messages): the problems of the first failing check, or [] when valid."""
    from analysis.data import is_simulated_dataset, line_ranges, parse_response

    def clean(v):
        return "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v).strip()

    t = table.copy()
    for column in ("dataset", "participant", "trial"):
        t[column] = t[column].map(clean)
    t["trial"] = t["trial"].str.upper()
    problems, values = [], []
    for line, d, p, tr, r in zip(t["line"], t["dataset"], t["participant"], t["trial"], t["response"]):
        if d not in allowed:
            hint = (" (simulated participants are not human data; pass allow_simulated=True "
                    "only in tests)" if is_simulated_dataset(d) else "")
            problems.append((line, f"unknown dataset {d!r}; expected one of {', '.join(sorted(allowed))}{hint}"))
        if p == "":
            problems.append((line, "empty participant id"))
        if tr not in TRIAL_IDS:
            problems.append((line, f"unknown trial id {tr!r}; expected one of the run's trials 1E, 1H, ..., 12H"))
        v = parse_response(r)
        if isinstance(v, str):
            problems.append((line, v))
        values.append(v)
    if problems:
        return sorted(problems, key=lambda q: q[0])
    t["response"] = values
    keys = ["dataset", "participant", "trial"]
    for _, group in t[t.duplicated(keys, keep=False)].groupby(keys, sort=False):
        first, *others = group["line"].tolist()
        for line in others:
            d, p, tr = group.iloc[0][keys]
            problems.append((line, f"duplicate response of participant {p!r} in dataset {d!r} "
                                   f"to trial {tr} (first given on line {first})"))
    if problems:
        return sorted(problems, key=lambda q: q[0])
    for (d, p), group in t.groupby(["dataset", "participant"], sort=False):
        absent = [tr for tr in TRIAL_IDS if tr not in set(group["trial"])]
        if absent:
            ls = group["line"].tolist()
            problems.append((min(ls), f"participant {p!r} in dataset {d!r} (rows on lines {line_ranges(ls)}) "
                                      f"is missing trial(s) {', '.join(absent)}"))
    return sorted(problems, key=lambda q: q[0])


_CELLS = ["5", " 3.5 ", "1e3", "-.5", "5.", "+7", "abc", "", "inf", "-Infinity", "nan", "1_000", "1e999",
          "0x10", "١", None, 2.5, float("nan"), 7]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_vectorised_validation_gives_the_row_by_row_verdicts(seed):
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(int(rng.integers(1, 4))):
        for t in TRIAL_IDS:
            rows.append({"dataset": "time", "participant": f"p{p}", "trial": t, "response": str(rng.normal())})
    table = pd.DataFrame(rows, dtype=object)  # cells of any type, as a user's DataFrame may hold
    for _ in range(int(rng.integers(0, 4))):  # a few faults of each kind, or none
        k, kind = int(rng.integers(len(table))), int(rng.integers(6))
        if kind == 0:
            table.at[k, "dataset"] = str(rng.choice(["tme", "build", " difficulty ", "simulated-time", ""]))
        elif kind == 1:
            table.at[k, "participant"] = str(rng.choice(["", " p0", "p9"]))
        elif kind == 2:
            table.at[k, "trial"] = str(rng.choice(["13E", "1e", " 7h", "", "E1"]))
        elif kind == 3:
            table.at[k, "response"] = _CELLS[int(rng.integers(len(_CELLS)))]
        elif kind == 4:
            table = pd.concat([table, table.iloc[[k]]], ignore_index=True)
        else:
            table = table.drop(index=k).reset_index(drop=True)
    table["line"] = np.arange(len(table)) + 2
    expected = [f"human data: line {line}: {msg}" for line, msg in
                _reference_validation(table, {"difficulty", "time", "build"})]
    if expected:
        with pytest.raises(HumanDataError) as err:
            validate_human_data(table)
        assert list(err.value.problems) == expected
    else:
        clean = validate_human_data(table)
        assert np.array_equal(clean["response"].to_numpy(), table["response"].astype(float).to_numpy())

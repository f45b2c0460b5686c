"""Eq. 1 with risk through the build in place of R (analysis, --risk-measure):
the fit prefers the build-risk aggregate that SIMULATED participants were drawn
from over the paper's final-state risk. No human data here."""
import numpy as np
import pandas as pd
import pytest

from analysis import TRIAL_IDS, run_analysis, simulate_participants
from analysis.models import RISK_MEASURES, ModelInputError, design_matrix, measure_at_sigma, risk_inputs

SIGMAS = (0.065, 0.1)
E = pd.Series(np.random.default_rng(0).uniform(1, 10, 24), index=list(TRIAL_IDS))


def synthetic_tables(seed=1):
    """A final-state risk table and build-risk aggregates whose max over stages
    ranks the trials differently from the final stage (as a disassembly would)."""
    rng = np.random.default_rng(seed)
    final = {s: rng.uniform(0, 0.3, 24) * (1 + 5 * (s - 0.065)) for s in SIGMAS}
    extra = rng.uniform(0, 0.6, 24) * (rng.uniform(size=24) < 0.5)
    risk_rows, build_rows = [], []
    for s in SIGMAS:
        r_final = final[s]
        r_max = np.minimum(1, r_final + extra)
        measures = {"final": r_final, "max": r_max, "expected": r_final + 2 * extra,
                    "any": np.minimum(1, r_final + 1.5 * extra), "care": r_final + 0.5 * extra,
                    "sequential": np.minimum(1, r_final + 0.8 * extra)}
        for i, t in enumerate(TRIAL_IDS):
            risk_rows.append((t, s, r_final[i]))
            build_rows += [(t, s, m, measures[m][i]) for m in RISK_MEASURES]
    return (pd.DataFrame(risk_rows, columns=["trial", "sigma", "risk"]),
            pd.DataFrame(build_rows, columns=["trial", "sigma", "measure", "risk"]))


def test_measure_names_match_the_build_risk_module():
    from models.risk.build import MEASURES

    assert tuple(MEASURES) == RISK_MEASURES


@pytest.mark.slow  # fits on simulated studies
def test_fit_prefers_the_build_risk_model_the_participants_were_drawn_from(tmp_path):
    risk, build = synthetic_tables()
    as_risk = build[build["measure"] == "max"].drop(columns="measure")
    sim = simulate_participants(E, as_risk, (0.0, 1.0, 4.0), 0.065, 30, 2.0, np.random.default_rng(7))
    out = run_analysis(sim, E, risk, tmp_path, seed=0, n_boot=200, jobs=1, sigma=0.065, build_risk=build,
                       figures=False)
    fits = out["fits"].set_index(["dataset", "model"])
    summary = out["bootstrap_summary"]
    for m in RISK_MEASURES:  # each aggregate is its own model in the bootstrap table
        assert {f"full[{m}]", f"risk[{m}]"} <= set(summary["model"])
    tests = out["bootstrap_tests"].set_index(["dataset", "model_a", "model_b"])
    for dataset in sim["dataset"].unique():
        assert fits.loc[(dataset, "full[max]"), "r"] > fits.loc[(dataset, "full"), "r"]
        assert fits.loc[(dataset, "full[max]"), "r"] >= fits.loc[(dataset, "full[care]"), "r"]
        # final-stage aggregate is the final-state risk: same fit
        assert fits.loc[(dataset, "full[final]"), "r"] == pytest.approx(fits.loc[(dataset, "full"), "r"])
        row = tests.loc[(dataset, "full[max]", "full")]
        assert row["better"] == "full[max]" and row["p_value"] < 0.05
    assert out["settings"]["build_risk_sigma"].iloc[0] == pytest.approx(0.065)


def test_risk_measure_replaces_r_in_the_plain_models(tmp_path):
    risk, build = synthetic_tables()
    as_risk = build[build["measure"] == "any"].drop(columns="measure")
    sim = simulate_participants(E, as_risk, (0.0, 1.0, 4.0), 0.1, 20, 1.0, np.random.default_rng(3),
                                datasets=("time",))
    out = run_analysis(sim, E, risk, tmp_path, seed=0, n_boot=50, jobs=1, sigma=0.1, build_risk=build,
                       risk_measure="any", figures=False)
    fits = out["fits"].set_index("model")
    assert fits.loc["full", "r"] == pytest.approx(fits.loc["full[any]", "r"])
    assert out["settings"]["risk_measure"].iloc[0] == "any"
    with pytest.raises(ValueError, match="needs the build-risk table"):
        run_analysis(sim, E, risk, tmp_path, seed=0, n_boot=10, jobs=1, sigma=0.1, risk_measure="max",
                     figures=False)


def test_probability_measures_above_one_are_refused_but_expected_collapses_may_exceed_one():
    _, build = synthetic_tables()
    bad = build.copy()
    bad.loc[(bad["measure"] == "expected") & (bad["trial"] == "3H"), "risk"] = 1.7
    assert measure_at_sigma(bad, 0.065, "expected")["3H"] == pytest.approx(1.7)
    bad.loc[(bad["measure"] == "max") & (bad["trial"] == "3H"), "risk"] = 1.7
    with pytest.raises(ModelInputError, match="'max' of trial 3H .* above 1"):
        measure_at_sigma(bad, 0.065, "max")
    inputs = risk_inputs(measure_at_sigma(build, 0.065, "final"), build, 0.065)
    X = design_matrix("full[expected]", E, inputs)
    R = inputs["expected"].to_numpy()
    assert np.allclose(X[:, 2], E.to_numpy() * R) and np.allclose(X[:, 1], E.to_numpy() * (1 - R))
    with pytest.raises(ModelInputError, match="no model full\\[often\\]"):
        design_matrix("full[often]", E, inputs)

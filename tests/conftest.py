"""Shared fixtures: the trials (loaded once per session, not at import time), the
synthetic effort and risk tables of the analysis tests, and the rule that makes
Drake-engine cases slow.

    python -m pytest -q                 # everything
    python -m pytest -q -m "not slow"   # the fast subset (README: how long each takes)
"""
import numpy as np
import pandas as pd
import pytest

from lgp.paper import SIGMA_GRID, TRIAL_IDS


def pytest_collection_modifyitems(items):
    """A case run with the Drake or a PhysX engine (a parameter "drake", "physx",
    "physx:...") is slow: Drake's hydroelastic contact at 1 ms steps costs seconds
    per scene, and PhysX is an optional extra; the fast subset checks MuJoCo."""
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        if any(isinstance(v, str) and (v == "drake" or v.split(":")[0] == "physx") for v in params.values()):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def trials():
    """The paper's 24 trials by id (stimuli.load_all, once per session)."""
    import stimuli

    loaded = {t.id: t for t in stimuli.load_all()}
    return {tid: loaded[tid] for tid in TRIAL_IDS}


# ----------------------------------------------------------------------------- synthetic model output (analysis tests)


def synthetic_effort(seed=0) -> pd.Series:
    """24 positive efforts, keyed by trial id (stand-in for the planner's output)."""
    return pd.Series(np.random.default_rng(seed).uniform(1, 10, 24), index=list(TRIAL_IDS))


def synthetic_risk(seed=0, sigmas=SIGMA_GRID) -> pd.DataFrame:
    """Risk per trial and sigma: a logistic in sigma around a per-trial threshold, so
    each trial's risk increases with sigma and the ranking of trials changes with it
    (if R(sigma) were c(sigma) R0, Eq. 1 would fit every sigma equally well)."""
    threshold = np.random.default_rng(seed + 100).uniform(0.04, 0.12, 24)
    return pd.DataFrame([(t, s, 1 / (1 + np.exp(-(s - threshold[i]) / 0.01)))
                         for s in sigmas for i, t in enumerate(TRIAL_IDS)],
                        columns=["trial", "sigma", "risk"])


@pytest.fixture(scope="session")
def make_effort():
    """synthetic_effort(seed): 24 positive efforts keyed by trial id."""
    return synthetic_effort


@pytest.fixture(scope="session")
def make_risk():
    """synthetic_risk(seed, sigmas): a tidy (trial, sigma, risk) table, logistic in sigma."""
    return synthetic_risk

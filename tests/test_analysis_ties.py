"""The chosen sigma does not hang on the CPU: RMSEs that tie (relative difference
below 1e-9) go to the smaller sigma wherever a sigma is chosen
(analysis.sigma.least_sigma_index), so rounding noise of 1 ulp, or another BLAS
kernel, cannot move it."""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from analysis import TRIAL_IDS, choose_sigma
from analysis.crossval import cross_validate, make_folds
from analysis.sigma import least_sigma_index


def one_risky_trial_risk(sigmas=(0.05, 0.065, 0.08, 0.1)) -> np.ndarray:
    """(S, 24) risk: only 1E ever falls, more with sigma. Whenever 1E is trained on,
    every sigma's E*R column is a multiple of the same spike: Eq. 1 fits every sigma
    exactly equally well, a true tie that only rounding can break."""
    R = np.zeros((len(sigmas), 24))
    R[:, 0] = np.linspace(0.2, 0.8, len(sigmas))
    return R


def test_least_sigma_index_breaks_ties_to_the_smallest_sigma_and_skips_nan():
    v = np.array([[3.0, 1.0 + 1e-12, 1.0, 2.0], [np.nan, 5.0, 4.0, 4.0 * (1 + 1e-6)]])
    assert least_sigma_index(v, axis=1).tolist() == [1, 2]
    assert int(least_sigma_index([0.0, 1e-17, 0.0])) == 0        # exact fits tie at zero too
    assert int(least_sigma_index([2.0, 1.0])) == 1                 # a real difference still wins


def test_a_one_ulp_perturbation_of_the_responses_never_moves_a_tied_sigma(make_effort):
    E = make_effort().to_numpy()
    R = one_risky_trial_risk()
    rng = np.random.default_rng(5)
    Y = rng.normal(size=(1, 2, 24)) + E
    # 40 copies, each entry nudged up or down by one ulp (or left): the same data to rounding.
    nudges = rng.integers(-1, 2, size=(40, 2, 24))
    Yp = np.where(nudges > 0, np.nextafter(Y, np.inf), np.where(nudges < 0, np.nextafter(Y, -np.inf), Y))
    _, chosen, test = cross_validate(Yp, E, {"R": R}, ["full", "effort"], "leave-one-pair-out")
    trains_1E = np.array([0 not in held for held in test])
    assert trains_1E.sum() == 11
    # Every fold that trains on 1E is a tie: the smallest sigma, in every copy.
    assert (chosen["R"][:, trains_1E] == 0).all()
    # The fold that holds 1E out has R = 0 on all training trials: also a tie.
    assert (chosen["R"][:, ~trains_1E] == 0).all()


def test_the_pooled_sigma_of_tied_profiles_is_the_smallest():
    profile = pd.DataFrame({"dataset": ["a"] * 3 + ["b"] * 3, "sigma": [0.05, 0.06, 0.07] * 2,
                            "rmse": [0.5, 0.4, 0.4 * (1 + 1e-12), 0.3, 0.2 * (1 + 1e-12), 0.2]})
    choice = choose_sigma(profile).set_index("dataset")["sigma"]
    assert choice["a"] == 0.06 and choice["b"] == 0.06 and choice["pooled"] == 0.06


SCRIPT = textwrap.dedent("""
    import numpy as np
    from analysis.crossval import cross_validate, risk_grid
    from tests.test_analysis_compare import zero_heavy_risk
    from tests.conftest import synthetic_effort
    E = synthetic_effort().to_numpy()
    out = []
    for seed in range(4):
        grid = risk_grid(zero_heavy_risk(seed))
        Y = np.random.default_rng(3).normal(size=(3, 2, 24)) + E
        for scheme in ("leave-one-pair-out", "leave-one-trial-out"):
            _, chosen, _ = cross_validate(Y, E, {"R": grid.risk}, ["full", "effort", "risk"], scheme)
            out.append(chosen["R"].ravel())
    print(" ".join(map(str, np.concatenate(out))))
""")


@pytest.mark.slow
def test_two_blas_core_types_choose_the_same_sigmas():
    """OPENBLAS_CORETYPE SkylakeX (AVX-512) vs Haswell: different kernels, different
    rounding; the sigma chosen in every fold is the same."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    runs = {}
    for core in ("SkylakeX", "Haswell"):
        env = dict(os.environ, OPENBLAS_CORETYPE=core, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
        done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=root, env=env, capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stderr
        runs[core] = done.stdout.split()
    assert len(runs["SkylakeX"]) == 4 * 2 * (3 * 12 + 3 * 24)
    assert runs["SkylakeX"] == runs["Haswell"]

"""Physical risk (paper, "Modeling physical risk"): how likely a Finish state B is
to fall when every block is nudged by Gaussian noise and the scene is simulated
for 4 s. See docs/risk.md for the noise rule, the fall rule and the engines.

    from models.risk import SIGMA_GRID, RiskModel, physical_risk, risk_table
    physical_risk(scene, sigma=0.065, n_sims=100, seed=0) # fraction of falls
    physical_risk(scene, 0.065, model=RiskModel("physx", fall_rule="3d"))  # another engine and fall rule
    risk_table(stimuli.load_all(), SIGMA_GRID, n_sims=100)# tidy (trial, sigma) table
"""
from models.risk.core import (  # noqa: F401
    UnstableSceneError,
    check_stable,
    physical_risk,
    risk_curve,
    risk_table,
    simulate_grid,
    summarise,
)
from lgp.paper import N_SIMS, SIGMA_GRID  # noqa: F401  (re-exported for convenience)
from models.risk.engine import (  # noqa: F401
    DURATION,
    ENGINES,
    PROFILES,
    EngineUnavailableError,
    Rollout,
    available_engines,
    engine_name,
    get_engine,
)
from models.risk.model import (  # noqa: F401
    DEFAULT_ENGINE,
    DEFAULT_MODEL,
    FALL_RULES,
    FALL_THRESHOLD,
    MODEL_COLUMNS,
    NOISE_RULES,
    FallRule,
    Noise,
    RiskModel,
)
from models.risk.noise import draw_normals, perturb, perturb_from_normals  # noqa: F401
from models.risk.static import static_stable  # noqa: F401
#: Risk through the build (beyond the paper; models.risk.build), re-exported lazily:
#: build risk plans stages with the logic layer, and importing it here would make
#: every risk result depend on the planner's source (lgp.app.cache keys by imports).
_BUILD = ("MEASURES", "build_risk", "build_risk_aggregates", "build_risk_table", "measure_table", "plan_stages",
          "stage_curve")


def __getattr__(name: str):
    if name in _BUILD:
        from models.risk import build

        return getattr(build, name)
    raise AttributeError(f"module 'models.risk' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_BUILD))

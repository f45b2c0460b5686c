"""The risk model as one value: a `RiskModel` names the physics engine (with its
profile), the fall rule with its threshold and the noise rule, checked once when
it is made, as `lgp.planner.Design` is for the motion design. Every function
that simulates takes one, the tables record it (`MODEL_COLUMNS`) and the cache
key is derived from it (`RiskModel.record`).

The checks of the other inputs of a grid of noisy runs (sigma, run count, seed)
live here too, so that there is one rule each for the library, the build risk
and the noise rule.

    RiskModel()                                    # mujoco, horizontal > 0.25 d, lift
    RiskModel("physx", "game-defaults")            # an engine and its profile
    RiskModel(fall_rule="3d", fall_threshold=0.1, noise_rule="settle")
"""
from __future__ import annotations

from dataclasses import InitVar, dataclass
from enum import StrEnum

import numpy as np

from lgp.errors import InputError
from lgp.scene import Scene
from models.risk.engine import FALL_CERTAIN, engine_name, smallest_width

#: The engine used when none is named: the one that passes the faithfulness suite
#: with the better throughput (docs/risk.md).
DEFAULT_ENGINE = "mujoco"


class FallRule(StrEnum):
    """How a block's move is measured against the fall threshold: in the
    horizontal plane (the default: a block lifted by the noise that drops back
    onto its support has not fallen) or in 3-D (the paper's wording, "the
    difference between the final and initial positions")."""

    HORIZONTAL = "horizontal"
    THREE_D = "3d"


class Noise(StrEnum):
    """How a noisy block's height is set once its horizontal place is known
    (models/risk/noise.py): "lift" (the paper's reading: never into its support,
    so it may start above it) or "settle" (on what lies beneath its new outline)."""

    LIFT = "lift"
    SETTLE = "settle"


#: A run falls when some block's centre ends farther than FALL_THRESHOLD (fraction
#: of the block size d) from where it started, measured by the fall rule.
FALL_THRESHOLD = 0.25
FALL_RULES: tuple[str, ...] = tuple(rule.value for rule in FallRule)
NOISE_RULES: tuple[str, ...] = tuple(rule.value for rule in Noise)
#: The columns a risk table records its model in, in table order; the fall rule's two.
FALL_COLUMNS: tuple[str, ...] = ("fall_rule", "fall_threshold")
MODEL_COLUMNS: tuple[str, ...] = ("engine", *FALL_COLUMNS, "noise_rule")


def _member(enum, value, what: str):
    try:
        return enum(value)
    except ValueError:
        raise InputError(f"unknown {what} {value!r}; known rules: {', '.join(enum)}") from None


def fall_certain(threshold: float = FALL_THRESHOLD) -> float:
    """Horizontal move (units of d) after which a run stops as a fall: FALL_CERTAIN,
    or twice the threshold if that is larger (a rocking tower can carry its top
    block past the threshold and back; horizontal distance never exceeds 3-D
    distance, so the stop is a fall under either rule)."""
    return max(FALL_CERTAIN, 2.0 * threshold)


def check_threshold(value) -> float:
    """A fall threshold in units of the block size d: a finite number > 0."""
    if isinstance(value, bool):
        raise InputError(f"fall threshold must be a number (units of the block size d), got {value!r}")
    try:
        threshold = float(value)
    except (TypeError, ValueError):
        raise InputError(f"fall threshold must be a number (units of the block size d), got {value!r}") from None
    if not threshold > 0 or not np.isfinite(threshold):
        raise InputError(f"fall threshold must be > 0 (units of the block size d), got {value!r}")
    return threshold


@dataclass(frozen=True)
class RiskModel:
    """The physics engine and the rules a noisy run is simulated and judged by.

    `engine`: a registry name (models.risk.engine.ENGINES; None: DEFAULT_ENGINE);
    `profile` (given when made, not kept): the engine's profile, folded into the
    name ("physx" with "game-defaults" is "physx:game-defaults"). `fall_rule`:
    FallRule; `fall_threshold`: how far (units of d) a block centre must move for
    the run to fall; `noise_rule`: Noise. Checked when made (InputError naming
    the rule; EngineUnavailableError for a missing optional engine); frozen, so
    it stays checked, and hashable."""

    engine: str = DEFAULT_ENGINE
    profile: InitVar[str | None] = None
    fall_rule: FallRule = FallRule.HORIZONTAL
    fall_threshold: float = FALL_THRESHOLD
    noise_rule: Noise = Noise.LIFT

    def __post_init__(self, profile):
        object.__setattr__(self, "engine", engine_name(DEFAULT_ENGINE if self.engine is None else self.engine, profile))
        object.__setattr__(self, "fall_rule", _member(FallRule, self.fall_rule, "fall rule"))
        object.__setattr__(self, "fall_threshold", check_threshold(self.fall_threshold))
        object.__setattr__(self, "noise_rule", _member(Noise, self.noise_rule, "noise rule"))

    @classmethod
    def of(cls, model: "RiskModel | str | None") -> "RiskModel":
        """`model` itself, the default model (None), or the default rules with
        the engine named by a string (a shorthand: ``check_stable(scene, "drake")``)."""
        if isinstance(model, RiskModel):
            return model
        if model is None or isinstance(model, str):
            return cls(model)
        raise TypeError(f"a risk model must be a models.risk.RiskModel or an engine name, got {model!r}")

    @classmethod
    def from_args(cls, args) -> "RiskModel":
        """The model of a command line's parsed arguments (or a run's settings):
        anything with engine, profile, fall_rule, fall_threshold and noise_rule."""
        return cls(args.engine, args.profile, args.fall_rule, args.fall_threshold, args.noise_rule)

    def fall_distance(self, scene: Scene) -> float:
        """Distance (m) a block centre of `scene` must move for a run to fall."""
        return self.fall_threshold * smallest_width(scene)

    @property
    def stop_distance(self) -> float:
        """Horizontal move (units of d) after which a run stops as a certain fall
        (fall_certain): what an unperturbed rollout depends on."""
        return fall_certain(self.fall_threshold)

    def displacement(self, rollout) -> np.ndarray:
        """Per-block distance (m) between final and start centre, measured by the fall rule."""
        return rollout.horizontal_displacement() if self.fall_rule is FallRule.HORIZONTAL else rollout.displacement_3d()

    def record(self) -> dict:
        """The model as the tables and the cache keys record it (MODEL_COLUMNS), plain values."""
        return dict(zip(MODEL_COLUMNS, (self.engine, self.fall_rule.value, self.fall_threshold, self.noise_rule.value)))

    def judged_by(self, judge: "RiskModel") -> "RiskModel":
        """This engine and noise rule with the fall rule and threshold of `judge`."""
        return RiskModel(self.engine, None, judge.fall_rule, judge.fall_threshold, self.noise_rule)

    def rejudge(self, runs, d: float):
        """A per-run table (RUN_COLUMNS) with `fell` decided again by this model's
        fall rule from its displacement columns (`d`: the block size, m). Exact
        when the runs were simulated with the same early-stop distance
        (stop_distance), e.g. any two thresholds <= 0.5 d."""
        if "fall_threshold" in runs and (runs["fall_threshold"].map(fall_certain) != self.stop_distance).any():
            raise InputError(f"runs simulated with early stops for another fall threshold cannot be re-judged at "
                             f"{self.fall_threshold:g} d")
        column = "max_displacement" if self.fall_rule is FallRule.HORIZONTAL else "max_displacement_3d"
        return runs.assign(fell=runs[column] > self.fall_threshold * d, fall_rule=self.fall_rule.value,
                           fall_threshold=self.fall_threshold)

    @property
    def fall_text(self) -> str:
        """The fall rule in a few words: 'horizontal displacement > 0.25 d'."""
        return f"{self.fall_rule} displacement > {self.fall_threshold:g} d"

    def describe(self) -> str:
        """The rules in a few words, for logs: 'horizontal fall rule at 0.25 d, lift noise rule'."""
        return f"{self.fall_rule} fall rule at {self.fall_threshold:g} d, {self.noise_rule} noise rule"


DEFAULT_MODEL = RiskModel()


def check_sigma(sigma) -> float:
    """A noise SD in units of the block size d: a finite number in [0, 1] (0: the
    unperturbed scene; the command lines take (0, 1]). Beyond 1 d the noise moves
    blocks by more than their size and the perturbed positions overflow long
    before sigma = 1e308; inf and nan are no noise level."""
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.integer, np.floating)):
        raise InputError(f"sigma must be a number in [0, 1] (units of the block size d), got {sigma!r}")
    value = float(sigma)
    if not (np.isfinite(value) and 0 <= value <= 1):
        raise InputError(f"sigma must be a finite number in [0, 1] (units of the block size d), got {sigma!r}")
    return value


def check_n_sims(n_sims) -> int:
    """A count of runs: a whole number >= 1 (not 2.5, not the text '4', not True)."""
    if isinstance(n_sims, bool) or not isinstance(n_sims, (int, np.integer)):
        raise InputError(f"n_sims must be a whole number >= 1 (runs per sigma; risk is falls / n_sims), got {n_sims!r}")
    if n_sims < 1:
        raise InputError(f"need n_sims >= 1 runs (risk is falls / n_sims), got {n_sims}")
    from lgp.cli import MAX_N_SIMS

    if n_sims > MAX_N_SIMS:  # the command line's limit: the noise alone would need n_sims x 24 bytes per block
        raise InputError(f"n_sims {int(n_sims):,} is more than the {MAX_N_SIMS:,} allowed (lgp.cli.MAX_N_SIMS): "
                         f"the noise of a 10-block scene alone would take {int(n_sims) * 240 / 2**30:.3g} GiB")
    return int(n_sims)


def check_seed(seed) -> None:
    """A seed: a whole number >= 0 or a numpy Generator. None is refused: numpy
    would seed from the operating system, and the same call would give other
    numbers every time (the project promises same seed, same numbers)."""
    if isinstance(seed, np.random.Generator):
        return
    if seed is None:
        raise InputError("seed=None would draw irreproducible numbers (numpy seeds from the operating system); "
                         "give a whole number >= 0 or a numpy.random.Generator")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a whole number >= 0 or a numpy.random.Generator, got {seed!r}")

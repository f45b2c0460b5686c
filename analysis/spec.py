"""Which model a table row means: a typed `ModelSpec` (base model, risk measure)
instead of parsing names like ``full[max]`` wherever models are fitted.

Bases:

* ``full``: Eq. 1, y = b0 + b1 E (1 - R) + b2 E R;
* ``effort``: y = b0 + b1 E;
* ``risk``: y = b0 + b1 R;
* a heuristic predictor h of analysis.heuristics.FEATURES (``height``,
  ``blocks``, ...): y = b0 + b1 h;
* ``effort+h`` for a heuristic h: y = b0 + b1 E + b2 h, the competitor of Eq. 1
  with the same number of parameters and no physics of risk.

`risk` is the build-risk aggregate standing in for R (``full[max]``; None: the
final-state risk table), only for the bases that read R. A spec's `name` is the
string every table prints (``full``, ``full[max]``, ``effort+height``), so
outputs keep their model names.
"""
from __future__ import annotations

from dataclasses import dataclass

#: The heuristic predictors, in table order.
FEATURES: tuple[str, ...] = ("height", "blocks", "stacked", "distance", "actions", "depth")
#: What each predictor stands for, one sentence each (tables, figures, docs).
FEATURE_MEANING: dict[str, str] = {
    "height": "taller targets are harder: B's height in block levels",
    "blocks": "more blocks are harder: the number of blocks in B",
    "stacked": "stacking is what is hard: the number of B's blocks resting on another block",
    "distance": "carrying is what is hard: total distance the assigned blocks travel from A to B (m)",
    "actions": "every grasp and place costs the same: the number of actions of the symbolic plan",
    "depth": "deep support chains are hard: the longest chain of blocks resting on one another in B",
}

#: Bases that read risk R (and so a sigma).
RISK_BASES: tuple[str, ...] = ("full", "risk")
#: Aggregates of risk through the build that may stand in for R (analysis.models.RISK_MEASURES).
RISK_MEASURES: tuple[str, ...] = ("final", "max", "expected", "any", "care", "sequential")
#: The composite competitors of Eq. 1 (effort plus one heuristic).
COMPOSITES: tuple[str, ...] = ("effort+height", "effort+stacked")
#: The heuristic models of every comparison: each predictor alone, then the composites.
HEURISTIC_MODELS: tuple[str, ...] = FEATURES + COMPOSITES


class ModelSpecError(ValueError):
    """An unknown model base or risk measure: names what was asked and what exists."""


@dataclass(frozen=True)
class ModelSpec:
    """One model: `base` (module docstring) and the build-risk `risk` measure
    standing in for R (None: the final-state risk table)."""

    base: str
    risk: str | None = None

    def __post_init__(self):
        if self.feature is None and self.base not in ("full", "effort", "risk"):
            raise ModelSpecError(f"unknown model {self.base!r}; bases: full, effort, risk, "
                                 f"{', '.join(FEATURES)}, effort+<one of those>")
        if self.risk is not None:
            if self.base not in RISK_BASES or self.risk not in RISK_MEASURES:
                raise ModelSpecError(f"no model {self.base}[{self.risk}]: bases {', '.join(RISK_BASES)}, "
                                     f"measures {', '.join(RISK_MEASURES)}")

    @classmethod
    def parse(cls, name: "str | ModelSpec") -> "ModelSpec":
        """'full[max]' -> ModelSpec('full', 'max'); 'effort+height' -> ModelSpec('effort+height')."""
        if isinstance(name, ModelSpec):
            return name
        name = str(name)
        if name.endswith("]") and "[" in name:
            base, measure = name[:-1].split("[", 1)
            return cls(base, measure)
        return cls(name)

    @property
    def name(self) -> str:
        return self.base if self.risk is None else f"{self.base}[{self.risk}]"

    def __str__(self) -> str:
        return self.name

    @property
    def feature(self) -> str | None:
        """The heuristic predictor this model reads (``height`` of effort+height), or None."""
        b = self.base[len("effort+"):] if self.base.startswith("effort+") else self.base
        return b if b in FEATURES else None

    @property
    def reads_effort(self) -> bool:
        return self.base in ("full", "effort") or self.base.startswith("effort+")

    @property
    def reads_risk(self) -> bool:
        return self.base in RISK_BASES

    @property
    def source(self) -> str | None:
        """The risk source of analysis.crossval ("R" or the measure), None if no risk."""
        return (self.risk or "R") if self.reads_risk else None

    @property
    def n_parameters(self) -> int:
        """Coefficients including the intercept: 3 for Eq. 1 and effort+h, else 2."""
        return 3 if self.base == "full" or self.base.startswith("effort+") else 2

    @property
    def meaning(self) -> str:
        """One sentence on what the model stands for."""
        if self.base == "full":
            return "Eq. 1: risky effort costs differently from safe effort (physics of effort and risk)"
        if self.base == "effort":
            return "physical effort alone (kinetic energy of the planned motion)"
        if self.base == "risk":
            return "physical risk alone (chance that B falls under noise)"
        f = self.feature
        if self.base.startswith("effort+"):
            return f"effort plus a no-physics story: {FEATURE_MEANING[f]}"
        return FEATURE_MEANING[f]

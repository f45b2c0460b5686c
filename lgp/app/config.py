"""The settings of one `python -m lgp.reproduce` run, built once: a RunConfig.

`lgp.reproduce.parse_args` checks the command line and ends with
`RunConfig.from_args`: every setting the user left out gets its default here,
from the constant's one home (lgp.paper for M, N, the sigma grid and the
bootstrap; analysis for the permutations and recovery studies; models.risk for the fall rule; the planner's design for approach
height and slices; --quick's smaller values in QUICK). The run, the report, the
page and the sensitivity sections read the fields; none keeps a default of its own.
"""
from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields
from typing import Any

from analysis.data import MAX_PARTICIPANTS
from analysis.permutation import N_PERM
from analysis.recovery import N_STUDIES
from lgp.executor import default_jobs
from lgp.paper import N_BOOT, N_SIMS, SAMPLES, SIGMA_GRID, SIGMA_GRIDS
from lgp.planner.design import APPROACH, SLICES_PER_PHASE, Design, EffortSpec, Planner
from models.risk.model import DEFAULT_MODEL, FALL_THRESHOLD, RiskModel

#: What --quick changes: a small version of the run, about a minute.
QUICK = {"samples": 3, "n_sims": 20, "sigmas": (0.05, 0.065, 0.08, 0.1), "n_boot": 200, "n_perm": 200,
         "recovery_studies": 50}


def _tuple(value):
    return None if value is None else tuple(value)


@dataclass(frozen=True)
class RunConfig:
    """One run's settings, every default filled in (fields in the command line's
    order; see `python -m lgp.reproduce --help`). `trials` None is the paper's 24
    (or every file of `stimuli`); `engine` None is the default engine;
    `build_sigmas` None is lgp.app.build_risk.BUILD_SIGMAS."""

    out: str = "results"
    stimuli: str | None = None
    trials: tuple[str, ...] | None = None
    samples: int = SAMPLES
    n_sims: int = N_SIMS
    sigmas: tuple[float, ...] = SIGMA_GRID
    engine: str | None = None
    profile: str | None = None
    fall_rule: str = DEFAULT_MODEL.fall_rule.value
    fall_threshold: float = FALL_THRESHOLD
    #: --sigma-grid: a named grid (lgp.paper.SIGMA_GRIDS) that sets `sigmas`; None: --sigmas or the paper's
    sigma_grid: str | None = None
    #: --noise-rule: lift (the default) or settle (models/risk/noise.py)
    noise_rule: str = DEFAULT_MODEL.noise_rule.value
    approach_height: float = APPROACH
    slices: int = SLICES_PER_PHASE
    planner: str = Planner.PAPER.value
    budget_solves: int | None = None
    budget_seconds: float | None = None
    jobs: int = field(default_factory=default_jobs)
    scheduler: str | None = None
    seed: int = 0
    n_boot: int = N_BOOT
    human_data: str | None = None
    #: --max-participants: most participants a human-data file may hold (analysis.data.MAX_PARTICIPANTS)
    max_participants: int = MAX_PARTICIPANTS
    quick: bool = False
    no_cache: bool = False
    no_replays: bool = False
    #: --verbose: a line per trial and stage as it finishes, and every file written at the end
    verbose: bool = False
    #: --into-existing: write into a folder with foreign content and no manifest, beside that content (issue 30)
    into_existing: bool = False
    risk_chunk: int = 6
    build_risk: bool = False
    build_sigmas: tuple[float, ...] | None = None
    risk_measure: str | None = None
    per_participant_sigma: bool = False
    #: --allow-simulated: a human-data file of SIMULATED participants (simulated-*) is read (tests only)
    allow_simulated: bool = False
    n_perm: int = N_PERM
    recovery: bool = False
    recovery_studies: int = N_STUDIES
    participant_betas: str = "shared"
    sensitivity: bool = False
    sensitivity_engines: tuple[str, ...] | None = None
    #: --sigma-from: summary.json of analysis.mental_jenga (lgp/app/sigma_from.py)
    sigma_from: str | None = None
    #: --planner search: its lgp.search.Budget (None for the paper's planner)
    budget: Any = None
    #: the command line as typed, for the report and the page
    command: str = ""

    @classmethod
    def default(cls, name: str):
        """The default of setting `name` (what the command line uses when it is not given)."""
        f = cls.__dataclass_fields__[name]
        return f.default_factory() if f.default_factory is not MISSING else f.default

    @property
    def design(self) -> Design:
        """The planner's motion design of the effort stage (checked)."""
        return Design(self.approach_height, self.slices)

    @property
    def effort_spec(self) -> EffortSpec:
        """The effort stage's motion design and planner (checked)."""
        return EffortSpec(self.design, self.planner, self.budget)

    @property
    def risk_model(self) -> RiskModel:
        """The risk model of the run (checked): engine and profile, fall rule, threshold, noise rule."""
        return RiskModel.from_args(self)

    @classmethod
    def from_args(cls, args) -> "RunConfig":
        """The RunConfig of parsed arguments (an argparse.Namespace, or anything with
        these attributes): None means "not given", so the default (or --quick's value)."""
        given = {f.name: getattr(args, f.name) for f in fields(cls) if getattr(args, f.name, None) is not None}
        if given.get("sigma_grid"):
            given["sigmas"] = SIGMA_GRIDS[given["sigma_grid"]]
        quick = QUICK if given.get("quick") else {}
        for name, value in quick.items():
            given.setdefault(name, value)
        for name in ("trials", "sigmas", "build_sigmas", "sensitivity_engines"):
            if name in given:
                given[name] = _tuple(dict.fromkeys(given[name]))  # 7h and 7H are one trial; a sigma given twice, one
        return cls(**given)

    def planner_choice(self) -> dict:
        """The planner of the run's effort (--planner): {} for the paper's pipeline
        (so its manifests name no planner and stay comparable with older runs), else
        {"planner": "search", "budget": lgp.search.Budget}."""
        return {} if self.planner == "paper" else {"planner": self.planner, "budget": self.budget}

    def parameters(self) -> dict:
        """Every setting but the command, by name, in the command line's order."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "command"}

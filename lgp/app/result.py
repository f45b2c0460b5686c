"""What a `python -m lgp.reproduce` run computed, as values: a `RunResult`.

`lgp.app.run.run` fills it, the writers (lgp.app.write: tables, report, page,
manifest) only read it. A feature beyond the paper is a `Stage` (`enabled(config)`,
`run(ctx) -> data`) whose data travel as a `Section` with the renderer that writes
them (files, report section, page section); lgp/app/build_risk.py and its
renderer lgp/app/build_risk_view.py are the pattern.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Protocol

import pandas as pd

from lgp.app.config import RunConfig


@dataclass(frozen=True)
class RunRecord:
    """How the run went: wall time per stage, the cache's counts, the compute time of
    its results, the software and engine settings, and where and when it ran."""

    #: wall time per stage (s), in the order the stages ran
    stages: dict[str, float]
    #: {(kind, outcome): n}: outcome hit, miss or recomputed, for result tables (effort, riskruns, ...)
    cache_counts: dict[tuple[str, str], int]
    #: {(kind, outcome): n} of the files the run reused or made (pictures, replays)
    cache_files: dict[tuple[str, str], int]
    cache_root: str
    #: (seconds spent computing the results this run used, results without a recorded time)
    compute: tuple[float, int]
    #: {"libraries": {name: version}, "engine": the risk engine's settings}
    software: dict
    #: versions of every library the page lists
    recorded_libraries: dict[str, str]
    finished: str
    machine: str
    load: str
    #: seconds from the start of the run to the end of its computing
    elapsed: float
    #: what the results depend on besides the settings: {"trial_files": {id: digest}, "human_data_sha256": ...}
    inputs: dict = field(default_factory=dict)

    def count(self, outcome: str) -> int:
        """Lookups of result tables with `outcome` (hit, miss, recomputed)."""
        return sum(n for (_, o), n in self.cache_counts.items() if o == outcome)

    hits = property(lambda self: self.count("hit"), doc="result tables reused from the cache")
    misses = property(lambda self: self.count("miss"), doc="result tables computed")
    recomputed = property(lambda self: self.count("recomputed"), doc="damaged entries computed again")

    @property
    def files(self) -> dict[tuple[str, str], int]:
        return self.cache_files

    @property
    def root(self) -> Path:
        return Path(self.cache_root)


class Renderer(Protocol):
    def __call__(self, data: Any, view: "View") -> "Rendered": ...


@dataclass
class Section:
    """One feature's result: its stage's name, its data (no markdown, no HTML) and
    the renderer that writes them."""

    name: str
    data: Any
    render: Callable[[Any, "View"], "Rendered"]


@dataclass
class View:
    """What a renderer may use besides its section's data: the run's result and the
    folder it writes into."""

    result: "RunResult"
    out: Path


@dataclass
class Rendered:
    """What a renderer wrote and shows: the files, the report section (markdown), the
    page section (HTML, placed after the pair tables), the figures the page's figure
    section lists, and per-trial tables the trial cards show."""

    files: list[Path] = field(default_factory=list)
    report: str | None = None
    page: str | None = None
    figures: list[Path] = field(default_factory=list)
    card_tables: dict[str, pd.DataFrame] = field(default_factory=dict)


@dataclass
class Context:
    """What a stage may use: the run's settings, trials, executor and cache, the
    folder of files a stage's workers make (replays, pictures), the log, the core
    results so far and the sections of the stages before it (by name)."""

    config: RunConfig
    trials: list
    executor: Any
    cache: Any
    workdir: Path
    log: Callable[[str], None]
    core: dict[str, Any] = field(default_factory=dict)
    sections: dict[str, Section] = field(default_factory=dict)


class Stage(Protocol):
    """A feature of a run: `name`, `phase` ("compute": with the run's executor, before
    the analysis; "analysis": after it), `enabled(config)` and `run(ctx)` -> its data
    (None when it has nothing to show). lgp.app.run.stages pairs it with its renderer."""

    name: str
    phase: str

    def enabled(self, config: RunConfig) -> bool: ...

    def run(self, ctx: Context) -> Any: ...


@dataclass
class RunResult:
    """Everything a run computed: the tables the paper's pipeline makes, the
    analysis, the feature sections and the run record. Files made by workers (the
    replays and trial pictures) are named by their paths."""

    config: RunConfig
    trials: list
    effort_samples: pd.DataFrame
    effort: pd.DataFrame
    risk: pd.DataFrame
    #: sigma* per trial (models.risk.precision.required_precision)
    precision: pd.DataFrame
    #: the sigma of the pair table (the paper's, or the grid's middle)
    sigma: float
    #: the pair table at `sigma` (None: no pair has both trials in the run)
    pairs: pd.DataFrame | None
    #: "Pairs over sigma" (lgp.app.over_sigma.OverSigma), on the paper's 24 trials only
    over_sigma: Any
    #: the analysis (analysis.run.AnalysisResult): with human data, or the model-only figures on the paper's 24
    analysis: Any
    #: the human data were given (the analysis holds fits)
    human: bool
    sections: list[Section]
    replays: dict[str, Path] | None
    pictures: dict[str, Path] | None
    #: {name: text} of the docs the page links (carried into the output folder)
    docs: dict[str, str]
    #: {trial: (width, height)} of the trial pictures
    picture_sizes: dict[str, tuple[int, int]] = field(default_factory=dict)
    #: {pair: what it varies} of the paper's pairs in the run
    pair_names: dict = field(default_factory=dict)
    record: RunRecord | None = None

    def section(self, name: str) -> Section | None:
        """The section of the stage `name`, None when it did not run."""
        return next((s for s in self.sections if s.name == name), None)

    @property
    def fitted_sigma(self) -> float | None:
        """The sigma fitted to the human data (pooled), None without human data."""
        choice = self.analysis.get("sigma_choice") if self.human and self.analysis is not None else None
        if isinstance(choice, pd.DataFrame) and len(choice) and "sigma" in choice:
            return float(choice["sigma"].iloc[0])
        return None

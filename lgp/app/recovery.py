"""Model recovery, `python -m lgp.reproduce --recovery`: SIMULATED
studies from each model on this run's effort and risk tables
(analysis.recovery), a stage of lgp.app.run; its renderer writes them into
recovery/ as ``simulated_*`` (never beside a human-data analysis) with the report
section, and the page shows the figure and the table.
"""
from __future__ import annotations

from dataclasses import dataclass
import pandas as pd


@dataclass(frozen=True)
class Recovery:
    """The confusion table and the summary of the SIMULATED studies (analysis.recovery.recovery)."""

    confusion: pd.DataFrame
    summary: pd.DataFrame


def recovery_tables(analysis, effort_samples: pd.DataFrame, risk: pd.DataFrame, n_studies: int, seed: int,
                    jobs: int) -> Recovery:
    """Simulate and refit at the stated parameters and, with human data
    (`analysis` from analysis.run), at the ones fitted to each dataset at the
    analysis's sigma."""
    from analysis.crossval import risk_grid
    from analysis.recovery import fitted_parameters, recovery

    grid = risk_grid(risk)
    fitted = None
    if analysis is not None and "zscored" in analysis:
        fitted = fitted_parameters(analysis["zscored"], effort_samples, grid, float(analysis["settings"]["sigma"].iloc[0]))
    confusion, summary = recovery(effort_samples, grid, n_studies=n_studies, fitted=fitted, seed=seed, jobs=jobs)
    return Recovery(confusion, summary)


def render(data: Recovery, view):
    """The files of recovery/, the report section, and the figure for the page's figure section."""
    from analysis.compare_report import recovery_lines
    from analysis.recovery import write_recovery
    from lgp.app.report import markdown_table
    from lgp.app.result import Rendered

    paths = write_recovery(data.confusion, data.summary, view.out / "recovery")
    return Rendered(paths, "\n".join(recovery_lines(data.summary, data.confusion, markdown_table)),
                    figures=[p for p in paths if p.suffix == ".png"])


class _Stage:
    name, phase = "recovery", "analysis"

    def enabled(self, config) -> bool:
        return config.recovery

    def run(self, ctx):
        core = ctx.core
        if not core["paper"]:
            ctx.log("--recovery simulates studies of the paper's 24 trials; not all are in this run, so it is skipped")
            return None
        c = ctx.config
        data = recovery_tables(core["analysis"] if core["human"] is not None else None, core["paper_effort_samples"],
                               core["paper_risk"], c.recovery_studies, c.seed, c.jobs)
        return data


STAGE = _Stage()

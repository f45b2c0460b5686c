"""Model recovery, `python -m lgp.reproduce --recovery`: SIMULATED
studies from each model on this run's effort and risk tables
(analysis.recovery), written into recovery/ as ``simulated_*`` (never beside a
human-data analysis), and the report section.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd


def recovery_outputs(analysis: dict | None, effort_samples: pd.DataFrame, risk: pd.DataFrame, out: Path,
                     n_studies: int, seed: int, jobs: int) -> tuple[list[Path], str]:
    """Simulate and refit at the stated parameters and, with human data
    (`analysis` from run_analysis), at the ones fitted to each dataset at the
    analysis's sigma. Returns the paths written and the report section."""
    from analysis.compare_report import recovery_lines
    from analysis.crossval import risk_grid
    from analysis.recovery import fitted_parameters, recovery, write_recovery
    from lgp.app.report import markdown_table

    grid = risk_grid(risk)
    fitted = None
    if analysis is not None and "zscored" in analysis:
        fitted = fitted_parameters(analysis["zscored"], effort_samples, grid, float(analysis["settings"]["sigma"].iloc[0]))
    confusion, summary = recovery(effort_samples, grid, n_studies=n_studies, fitted=fitted, seed=seed, jobs=jobs)
    paths = write_recovery(confusion, summary, out / "recovery")
    return paths, "\n".join(recovery_lines(summary, confusion, markdown_table))


def list_files(analysis: dict, paths: list[Path]) -> None:
    """Add the recovery files to the analysis's file list (kind, path), so the page
    shows the figure with the other figures."""
    rows = pd.DataFrame([("figure" if p.suffix in (".png", ".pdf") else "table", str(p)) for p in paths],
                        columns=["kind", "path"])
    analysis["files"] = pd.concat([analysis["files"], rows], ignore_index=True)

"""The writers of a run: `write_all(result, out)` writes a RunResult's tables,
figures, analysis, feature sections, report.md and index.html into `out` (the
run's staging folder). They read only the RunResult: nothing is computed, read
back from disk or looked for here. The manifest is written by lgp.reproduce, which
owns the folder (lgp/owned.py).
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from lgp.app.files import write_csv_atomic
from lgp.app.report import write_report
from lgp.app.result import Rendered, RunResult, View


def write_all(result: RunResult, out: Path) -> list[Path]:
    """Every output of `result` under `out`; the paths written (folders for the page's files)."""
    out = Path(out)
    written = [write_csv_atomic(result.effort_samples, out / "effort_samples.csv"),
               write_csv_atomic(result.effort, out / "effort.csv"), write_csv_atomic(result.risk, out / "risk.csv"),
               write_csv_atomic(result.precision, out / "risk_precision.csv")]
    written += [Path(p) for p in (result.replays or {}).values()]
    if result.pairs is not None:
        from lgp.app.report import pairs_csv_table

        written.append(write_csv_atomic(pairs_csv_table(result.pairs), out / "pairs.csv"))
    over_figure = None
    if result.over_sigma is not None:
        from lgp.app import over_sigma

        written.append(write_csv_atomic(result.over_sigma.table, out / "pairs_over_sigma.csv"))
        over_figure = over_sigma.plot_risk_over_sigma(result.over_sigma.table, out / "figures" / "risk_over_sigma.png",
                                                      result.pair_names)
        written.append(over_figure)
    rendered = [section.render(section.data, View(result, out)) for section in result.sections]
    written += [p for r in rendered for p in r.files]
    analysis_files = _write_analysis(result, out)
    written += [Path(p) for p in analysis_files["path"]] if analysis_files is not None else []
    written.append(_write_report(result, out, rendered, over_figure is not None))
    written.append(_write_page(result, out, rendered, analysis_files, over_figure))
    return written


def _write_analysis(result: RunResult, out: Path) -> pd.DataFrame | None:
    """The analysis's tables and figures: into analysis/ with human data, else figures/ (the model-only figure)."""
    if result.analysis is None:
        return None
    from analysis.run import write_analysis

    return write_analysis(result.analysis, out / ("analysis" if result.human else "figures"))["files"]


def _write_report(result: RunResult, out: Path, rendered: list[Rendered], over: bool) -> Path:
    """report.md: the run's tables, then "Pairs over sigma" (or the required precision) and every section's."""
    from lgp.app import over_sigma

    if over:
        first = over_sigma.report_lines(result.over_sigma, result.precision, "figures/risk_over_sigma.png")
    else:
        first = over_sigma.precision_lines(result.precision)
    sections = ["\n".join(first)] + [r.report for r in rendered if r.report is not None]
    return write_report(out, result.config, result.effort, result.risk, result.pairs,
                        result.analysis if result.human else None, result.record.elapsed, result.record.software,
                        result.record.compute, sections)


def _write_page(result: RunResult, out: Path, rendered: list[Rendered], analysis_files: pd.DataFrame | None,
                over_figure: Path | None) -> Path:
    """index.html, with the figures written above and the sections' page parts and card tables."""
    from lgp.app.page import write_index

    figures = []
    if analysis_files is not None:
        figures = [Path(p) for k, p in analysis_files[["kind", "path"]].itertuples(index=False)
                   if k == "figure" and str(p).endswith(".png")]
    figures += [f for r in rendered for f in r.figures]
    cards = {name: df for r in rendered for name, df in r.card_tables.items()}
    pages = [r.page for r in rendered if r.page]
    return write_index(result, out, figures=figures, card_tables=cards, section_pages=pages, over_figure=over_figure)

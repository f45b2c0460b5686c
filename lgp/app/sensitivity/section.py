"""What a sensitivity section takes and gives: a `Context` (the run's settings,
trials, executor, cache, output folder) and a `Section` (markdown lines for
report.md, the tables it computed, the figures it draws) and the section's markdown
tables. A section computes; `write_sections` writes its tables and figures."""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from lgp.app.cache import Cache
from lgp.app.config import RunConfig


@dataclass
class Context:
    """What a section may use: the run's settings (lgp.app.config.RunConfig), its
    trials, executor and cache, the output folder, and `risk_key(engine, rule,
    threshold)` -> the risk cache-key inputs (lgp.app.stages.risk_key_inputs)."""

    args: RunConfig
    trials: list
    executor: object
    cache: Cache
    out: Path
    risk_key: Callable[..., dict]
    log: Callable[[str], None] = field(default=lambda m: print(m, file=sys.stderr, flush=True))
    #: lgp.app.stages.effort_tables (trials, samples, seed, executor, cache, spec=lgp.planner.EffortSpec)
    effort_tables: Callable[..., pd.DataFrame] | None = None


@dataclass
class Section:
    title: str
    lines: list[str]
    #: the tables to write, by file stem (<stem>.csv; the page's trial cards show those with a trial column)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    #: the figures to draw, by path relative to the output folder: draw(path) -> path
    figures: dict[str, Callable[[Path], Path]] = field(default_factory=dict)


def write_sections(sections: list[Section], out: Path) -> list[Path]:
    """Write every section's tables (<stem>.csv) and figures into `out`; the paths, in order."""
    from lgp.app.files import write_csv_atomic

    files = []
    for section in sections:
        files += [write_csv_atomic(table, out / f"{stem}.csv") for stem, table in section.tables.items()]
        files += [draw(out / relative) for relative, draw in section.figures.items()]
    return files


def markdown(df: pd.DataFrame) -> list[str]:
    """A table as markdown lines: numbers as :g, booleans as yes / no."""
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, row in df.iterrows():
        cells = []
        for v in row:
            if isinstance(v, (float, np.floating)):
                cells.append(f"{v:g}")
            elif isinstance(v, (bool, np.bool_)):
                cells.append("yes" if v else "no")
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return lines

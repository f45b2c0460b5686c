"""Sensitivity sections of the reproduction report (`python -m lgp.reproduce
--sensitivity`): how much the results move with choices the paper leaves open.

Each section is a function in SECTIONS taking a `Context` (the run's arguments,
trials, executor, cache, output folder) and returning a `Section` (markdown lines
for report.md and the files it wrote). A new sensitivity is one more function
appended to SECTIONS; `lgp.reproduce` runs them all.

The sections: risk by engine and fall rule (lgp/app/sensitivity/risk.py) and
effort by motion design (lgp/app/sensitivity/effort.py).
"""
from __future__ import annotations

from typing import Callable

from lgp.app.sensitivity.effort import (EFFORT_HEIGHTS, EFFORT_QUICK_SAMPLES, effort_designs,  # noqa: F401
                                        effort_section, effort_sensitivity_tables)
from lgp.app.sensitivity.risk import (COLUMNS, DEFAULT_RISK_ENGINES, NOISE_RULES, RISK_RULES, RISK_SIGMAS, risk_engines,  # noqa: F401
                                      risk_section, risk_sensitivity_figure, risk_sensitivity_summary,
                                      risk_sensitivity_table)
from lgp.app.sensitivity.section import Context, Section, write_sections  # noqa: F401


def add_arguments(parser) -> None:
    """The command-line options of the sensitivity sections."""
    parser.add_argument("--sensitivity", action="store_true",
                        help="also run the sensitivity sections, cached: risk by engine and fall rule (docs/risk.md) and "
                             "effort by motion design (approach legs 5 and 2 cm, none, twice the slices; docs/effort.md), "
                             "which plans every trial three more times and is slow (the clearance design most)")
    parser.add_argument("--sensitivity-engines", nargs="+", metavar="ENGINE",
                        help="engines of the risk sensitivity (default: mujoco, physx, physx:game-defaults when "
                             "installed; add drake to include it)")


def check_arguments(args) -> None:
    """ValueError for an unknown or uninstalled engine of --sensitivity-engines."""
    from models.risk import engine_name

    for name in args.sensitivity_engines or ():
        engine_name(name)


def run_sections(ctx: Context) -> list[Section]:
    return [section(ctx) for section in SECTIONS]


#: The report's sensitivity sections, in order (append new ones here).
SECTIONS: list[Callable[[Context], Section]] = [risk_section, effort_section]


def render(sections: list[Section], view):
    """The report sections of --sensitivity, its tables and figures written, and its tables for the trial cards."""
    from lgp.app.result import Rendered

    return Rendered(write_sections(sections, view.out), "\n".join("\n".join(s.lines) for s in sections),
                    card_tables={name: df for s in sections for name, df in s.tables.items()})


class _Stage:
    """--sensitivity as a stage of lgp.app.run: its sections compute; `render` writes their files."""

    name, phase = "sensitivity", "compute"

    def enabled(self, config) -> bool:
        return config.sensitivity

    def run(self, ctx):
        from lgp.app.stages import effort_tables, risk_key_inputs

        return run_sections(Context(ctx.config, ctx.trials, ctx.executor, ctx.cache, ctx.workdir, risk_key_inputs,
                                    ctx.log, effort_tables=effort_tables))


STAGE = _Stage()

__all__ = ["SECTIONS", "Context", "Section", "write_sections", "add_arguments", "check_arguments", "run_sections", "risk_section",
           "effort_section", "effort_designs", "effort_sensitivity_tables", "EFFORT_HEIGHTS",
           "risk_sensitivity_table", "risk_sensitivity_summary", "RISK_RULES", "RISK_SIGMAS", "NOISE_RULES"]

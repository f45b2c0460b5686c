"""Each participant's sigma, `python -m lgp.reproduce --human-data FILE
--per-participant-sigma`: analysis.fit_participant_sigma as a stage of
lgp.app.run; its renderer writes the table, the histogram and a report section.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from lgp.app.files import write_csv_atomic


@dataclass(frozen=True)
class ParticipantSigma:
    """Each participant's sigma (analysis.fit_participant_sigma), the betas rule and the command."""

    table: pd.DataFrame
    betas: str
    command: str


def participant_sigma_outputs(human: pd.DataFrame, effort_samples: pd.DataFrame, risk: pd.DataFrame, out: Path,
                              betas: str, command: str) -> tuple[list[Path], str]:
    """Each participant's sigma: table, histogram and report section, written into `out`."""
    from analysis import fit_participant_sigma

    return write_outputs(ParticipantSigma(fit_participant_sigma(human, effort_samples, risk, betas=betas), betas, command),
                         out)


def write_outputs(data: ParticipantSigma, out: Path) -> tuple[list[Path], str]:
    """The table, the histogram and the report section of `data`."""
    from analysis.figures import plot_participant_sigma

    table, betas, command = data.table, data.betas, data.command
    simulated = table["dataset"].astype(str).str.startswith("simulated-").any()
    prefix = "simulated_" if simulated else ""
    written = [write_csv_atomic(table, out / f"{prefix}participant_sigma.csv")]
    written += plot_participant_sigma(table, out / "figures")
    summary = (table.groupby("dataset", sort=False)
               .agg(participants=("participant", "size"), median_sigma=("sigma", "median"),
                    identified=("identified", "sum"),
                    median_interval_width=("sigma_high", "median"))
               .reset_index())
    widths = (table["sigma_high"] - table["sigma_low"]).groupby(table["dataset"]).median()
    summary["median_interval_width"] = summary["dataset"].map(widths)
    lines = ["## Each participant's sigma (beyond the paper)" + (" -- SIMULATED participants" if simulated else ""), "",
             f"Command: `{command}`. Betas: {betas} (analysis/participant_sigma.py). A participant counts as "
             "identified when the 95% profile-likelihood interval is narrower than the whole sigma range.", "",
             "| dataset | participants | median sigma | identified | median interval width |", "|---|---|---|---|---|"]
    for _, r in summary.iterrows():
        lines.append(f"| {r['dataset']} | {r['participants']} | {r['median_sigma']:.3f} | {int(r['identified'])} | "
                     f"{r['median_interval_width']:.3f} |")
    lines.append("")
    return written, "\n".join(lines)


def render(data: ParticipantSigma, view):
    from lgp.app.result import Rendered

    files, report = write_outputs(data, view.out)
    return Rendered(files, report)


class _Stage:
    name, phase = "participant_sigma", "analysis"

    def enabled(self, config) -> bool:
        return config.per_participant_sigma

    def run(self, ctx):
        from analysis import fit_participant_sigma
        core, c = ctx.core, ctx.config
        if not core["paper"]:
            ctx.log("--per-participant-sigma works on the paper's 24 trials; not all are in this run, so it is skipped")
            return None
        table = fit_participant_sigma(core["human"], core["paper_effort_samples"], core["paper_risk"],
                                      betas=c.participant_betas)
        return ParticipantSigma(table, c.participant_betas, c.command)


STAGE = _Stage()

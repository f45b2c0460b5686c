"""Each participant's sigma, `python -m lgp.reproduce --human-data FILE
--per-participant-sigma`: analysis.fit_participant_sigma, its table,
histogram and a report section.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from lgp.app.files import write_csv_atomic


def participant_sigma_outputs(human: pd.DataFrame, effort_samples: pd.DataFrame, risk: pd.DataFrame, out: Path,
                              betas: str, command: str) -> tuple[list[Path], str]:
    """Each participant's sigma: table, histogram and report section."""
    from analysis import fit_participant_sigma
    from analysis.figures import plot_participant_sigma

    table = fit_participant_sigma(human, effort_samples, risk, betas=betas)
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

"""report.md of a reproduce run, and the text of its pair tables.

`write_report` writes the settings, the engine with its settings, both times, the
effort and risk tables and the pair orderings; its last sections are
those of the run's feature stages (lgp.app.result.Rendered.report). The pair tables come
from analysis.pairs as numbers (RatioRange); `ratio_text` and `pairs_csv_table`
write them in words, for report.md and pairs.csv alike.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.files import write_text_atomic


def _num(x) -> str:
    return f"{float(x):.4g}"


def sigma_edge_warnings(analysis: dict | None) -> list[str]:
    """A warning for every chosen sigma (per dataset, pooled) at the edge of the
    grid it was chosen from: the best fit may lie outside the grid (widen --sigmas)."""
    if not isinstance(analysis, dict):
        return []
    choice, profile = analysis.get("sigma_choice"), analysis.get("sigma_profile")
    if not isinstance(choice, pd.DataFrame) or not isinstance(profile, pd.DataFrame) or not len(profile):
        return []
    lo, hi = float(profile["sigma"].min()), float(profile["sigma"].max())
    out = []
    for _, row in choice.iterrows():
        s = float(row["sigma"])
        if lo < hi and (np.isclose(s, lo) or np.isclose(s, hi)):
            out.append(f"the sigma chosen for {row['dataset']} ({_num(s)} d) is at the {'lower' if np.isclose(s, lo) else 'upper'} "
                       f"edge of the grid ({_num(lo)} to {_num(hi)} d): the best fit may lie outside it; widen --sigmas to find it")
    return out


def ratio_text(r) -> str:
    """An analysis.pairs.RatioRange in words: 'any', 'none', 'none (tie)', '> 1.09' or '< 0.5'."""
    if r.tie:
        return "none (tie)"
    if r.every:
        return "any"
    if r.empty:
        return "none"
    return f"> {r.low:.3g}" if r.high == math.inf else f"< {r.high:.3g}"


def pairs_csv_table(pairs: pd.DataFrame) -> pd.DataFrame:
    """A pair_orderings table as pairs.csv has it: the ratio range of Eq. 1 in words,
    in the column full_E_lt_H_for_b2_over_b1."""
    from analysis.pairs import RATIO_COLUMNS, ratio_ranges

    return pairs.drop(columns=list(RATIO_COLUMNS)).assign(
        full_E_lt_H_for_b2_over_b1=[ratio_text(r) for r in ratio_ranges(pairs)])


def _orders(pairs: pd.DataFrame, source: str) -> str:
    """'E < H in 10 of 12 pairs (tied: 6; reversed: 11)' from a pair table."""
    n = int(pairs[f"{source}_E_lt_H"].sum())
    notes = []
    for order, word in (("tie", "tied"), ("H<E", "reversed")):
        found = pairs.loc[pairs[f"{source}_order"] == order, "pair"].tolist()
        if found:
            notes.append(f"{word}: {', '.join(map(str, found))}")
    return f"E < H in {n} of {len(pairs)} pairs" + (f" ({'; '.join(notes)})" if notes else "")


def engine_description(engine: str | None, settings: dict | None = None) -> str:
    """The risk engine by name with its settings, e.g. 'mujoco 3.3.0 (timestep 0.002, ...)'."""
    from models.risk.core import DEFAULT_ENGINE
    from models.risk.engine import get_engine

    name = engine or DEFAULT_ENGINE
    settings = dict(get_engine(name).settings() if settings is None else settings)
    settings.pop("engine", None)
    version = settings.pop("version", None)
    text = ", ".join(f"{k} {v}" for k, v in settings.items())
    return f"{name}" + (f" {version}" if version else "") + (f" ({text})" if text else "") + \
        ("" if engine else " [the default engine]") + \
        (" [UNFAITHFUL profile: fails the faithfulness suite, docs/risk.md]" if settings.get("faithful") is False else "")


def markdown_table(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, row in df.iterrows():
        cells = [format(v, floatfmt) if isinstance(v, (float, np.floating)) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _design_text(approach_height: float | None, slices: int | None) -> str:
    """'5 cm approach legs, 20 slices per phase' (or the clearance design at height 0)."""
    from lgp.planner import APPROACH, SLICES_PER_PHASE

    h = APPROACH if approach_height is None else approach_height
    legs = f"{h * 100:g} cm approach legs" if h > 0 else "no approach legs (clearance constraint)"
    return f"{legs}, {SLICES_PER_PHASE if slices is None else slices} slices per phase"


def _pair_lines(pairs: pd.DataFrame, fitted: bool) -> list[str]:
    """The report's pair table, its tie rule and orderings (`fitted`: with human data)."""
    from analysis.pairs import TIE_REL

    lines = [
        f"## Easy/hard pairs (risk at sigma = {pairs['sigma'].iloc[0]:g} d)",
        "",
        markdown_table(pairs_csv_table(pairs).drop(columns=["sigma"])),
        "",
        f"Tie rule (one rule for this table, pairs.csv, the figures and docs/results.md): E and H are tied when "
        f"|H - E| <= {TIE_REL:g} x max(E, H), the plan-to-plan noise of effort (analysis.pairs.TIE_REL); "
        "a tie counts as not ordered. effort_rel_diff = (H - E) / E.",
        "",
        f"Effort: {_orders(pairs, 'effort')}. Risk: {_orders(pairs, 'risk')}. "
        "The paper's fitted full model ordered 11 of 12 (pair 11 the exception).",
        "",
    ]
    if not fitted:
        lines += ["Without human data there are no fitted betas, so the last column says for which ratios b2/b1 "
                  "(b1 > 0) Eq. 1 would order each pair E < H.", ""]
    else:
        lines += ["The last column says for which ratios b2/b1 (b1 > 0) Eq. 1 would order each pair E < H; the "
                  "fitted betas and the orderings they give are below.", ""]
    return lines


def write_report(out: Path, args, effort: pd.DataFrame, risk: pd.DataFrame, pairs: pd.DataFrame, analysis: dict | None,
                 elapsed: float, software: dict | None = None, compute: tuple[float, int] = (float("nan"), 0),
                 sections=()) -> Path:
    """report.md: settings, the engine with its settings, both times, the tables, the
    pair orderings under the one tie rule (analysis.pairs.TIE_REL), then `sections`
    (markdown: pairs over sigma, the feature sections)."""

    engine = engine_description(args.engine, (software or {}).get("engine"))
    wide = risk.pivot_table(index="trial", columns="sigma", values="risk").reindex(effort["trial"])
    wide.columns = [f"{s:g}" for s in wide.columns]
    compute_s, unknown = compute
    compute_text = (f"Compute time of these results {compute_s:.0f} s (wall time spent computing each cached effort and risk "
                    "result when it was computed" + (f"; {unknown} result(s) cached by an older version have no recorded time"
                                                     if unknown else "") + f"); this run took {elapsed:.0f} s.")
    lines = [
        "# Reproduction report",
        "",
        f"Settings: trials {len(effort)}, M = {args.samples} layouts, N = {args.n_sims} runs per sigma, "
        f"sigmas {', '.join(f'{s:g}' for s in args.sigmas)} (x d), "
        f"fall rule {args.risk_model.fall_text}, noise rule {args.risk_model.noise_rule}, seed {args.seed}, "
        f"effort planned with {_design_text(args.approach_height, args.slices)}"
        + (f", planner search ({args.budget})" if args.planner == "search" else "")
        + (" (--quick: a small version; numbers are noisier than the full run)" if args.quick else "") + ".",
        f"Risk engine: {engine or args.engine or 'default'}.",
        compute_text,
        "",
        "## Physical effort (J s: integral of the carried blocks' kinetic energy over time, 1 kg blocks)",
        "",
        markdown_table(effort),
        "",
        "## Physical risk (fraction of noisy runs that fall)",
        "",
        markdown_table(wide.reset_index(), ".2f"),
        "",
    ]
    if pairs is not None:
        lines += _pair_lines(pairs, analysis is not None)
    if analysis is None:
        lines += ["No human data given (`--human-data FILE`, format in docs/human-data.md): the fits of Eq. 1, "
                  "the sigma profile and the bootstrap need the responses, which are not public.", ""]
    else:
        lines += [f"**Warning**: {w}." for w in sigma_edge_warnings(analysis)] + ([""] if sigma_edge_warnings(analysis) else [])
        from analysis.compare_report import comparison_lines

        for key in ("sigma_choice", "fits", "bootstrap_summary", "bootstrap_tests"):
            if key in analysis and isinstance(analysis[key], pd.DataFrame) and len(analysis[key]):
                label = " (in-sample)" if key != "sigma_choice" else ""
                lines += [f"## {key.replace('_', ' ')}{label}", "", markdown_table(analysis[key]), ""]
        lines += comparison_lines(analysis, markdown_table)
        if "orderings" in analysis:
            lines += ["## Pair orderings by source (orderings.csv)", "", markdown_table(analysis["orderings"]), ""]
        if isinstance(analysis.get("skipped"), pd.DataFrame) and len(analysis["skipped"]):
            lines += ["## Left out for this trial set (skipped.csv)", "",
                      "These parts of the analysis need easy/hard pairs (trials nE and nH), which this trial set "
                      "lacks; the fits, sigma profile, bootstrap and the other tests are above.", "",
                      markdown_table(analysis["skipped"]), ""]
    if software:  # what the cache keys hold besides code and inputs: a reader can tell which library made the numbers
        lines += ["## Software", "", "Libraries: " + ", ".join(f"{k} {v}" for k, v in software["libraries"].items()) + ".",
                  "", f"Risk engine settings: `{json.dumps(software['engine'], sort_keys=True, default=str)}`.", ""]
    text = "\n".join(lines)
    if sections:
        text += "\n" + "\n".join(sections)
    return write_text_atomic(text, out / "report.md")

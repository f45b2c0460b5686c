"""The effort section of --sensitivity (`effort_section`): the effort of every
trial for each motion design of EFFORT_HEIGHTS (approach legs of 5 cm and 2 cm; 0 = no legs,
a clearance constraint instead) at the run's slices per phase, and for the run's
design at twice its slices (the next-finer setting of docs/effort.md), with the
H/E ratio of every pair under each design and whether the pair's order (tie rule
of analysis.pairs) differs from the run's design. Planned through the run's
effort stage, so cached per trial and design. With --quick, one layout per trial.
Writes effort_sensitivity.csv (one row per design and trial) and
effort_sensitivity_pairs.csv (one row per design and pair).
"""
from __future__ import annotations

import dataclasses

import time

import numpy as np
import pandas as pd

from lgp.app.sensitivity.section import Context, Section, markdown
from lgp.planner.design import APPROACH, Design

#: Approach heights (m) of the effort section: the default legs, shorter legs, and
#: none (the clearance design of lgp.planner).
EFFORT_HEIGHTS = (APPROACH, 0.02, 0.0)
#: Layouts per trial of the effort section with --quick (the clearance design
#: re-solves its carries and is the slow one).
EFFORT_QUICK_SAMPLES = 1


def effort_designs(args) -> list[tuple[str, float, int]]:
    """(label, approach_height, slices_per_phase) of the effort section; the run's
    design first."""
    h, S = float(args.approach_height), args.slices

    def label(height, slices):
        legs = f"legs {height * 100:g} cm" if height > 0 else "clearance (no legs)"
        return f"{legs}, {slices} slices"

    designs = [(label(h, S), h, S)]
    for height in EFFORT_HEIGHTS:
        if height != h:
            designs.append((label(height, S), height, S))
    designs.append((label(h, 2 * S), h, 2 * S))
    return designs


def effort_sensitivity_tables(ctx: Context) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(per design and trial, per design and pair, notes on designs that failed)."""
    from analysis import pair_table
    from lgp.paper import TRIAL_IDS
    from models.effort import converged

    args = ctx.args
    samples = EFFORT_QUICK_SAMPLES if args.quick else args.samples
    rows, notes = [], []
    for label, h, S in effort_designs(args):
        t0 = time.perf_counter()
        spec = dataclasses.replace(args.effort_spec, design=Design(h, S))
        try:
            table = ctx.effort_tables(ctx.trials, samples, args.seed, ctx.executor, ctx.cache,
                                      spec=spec)
        except Exception:  # a trial the planner cannot do with this design: the others, one by one (cached ones at once)
            parts = []
            for t in ctx.trials:
                try:
                    parts.append(ctx.effort_tables([t], samples, args.seed, ctx.executor, ctx.cache,
                                                   spec=spec))
                except Exception as e:  # said in the report and the table (effort NaN), not hidden
                    notes.append(f"{label}, {t.id}: {type(e).__name__}: {e}")
                    ctx.log(f"[sensitivity] effort, {label}, {t.id}: failed ({type(e).__name__})")
                    parts.append(pd.DataFrame([{"trial": t.id, "sample": 0, "effort": np.nan, "status": "failed"}]))
            table = pd.concat(parts, ignore_index=True)
        ctx.log(f"[sensitivity] effort, {label}: {len(table)} layouts in {time.perf_counter() - t0:.1f} s")
        g = table.groupby("trial", sort=False)
        for trial, df in g:
            rows.append({"design": label, "approach_height": h, "slices_per_phase": S, "trial": trial,
                         "effort": float(df["effort"].mean()), "samples": len(df),
                         "not_converged": int((~converged(df["status"]) & (df["status"] != "failed")).sum())})
    table = pd.DataFrame(rows, columns=["design", "approach_height", "slices_per_phase", "trial", "effort", "samples",
                                        "not_converged"])
    pairs = []
    base = None
    if {t.id for t in ctx.trials} >= set(TRIAL_IDS):
        for label, d in table.groupby("design", sort=False):
            effort = d.set_index("trial")["effort"]
            failed = set(effort.index[~np.isfinite(effort)])
            pt = pair_table(effort.fillna(1.0))  # failed trials: no ratio, no order (below)
            bad = [f"{p}E" in failed or f"{p}H" in failed for p in pt["pair"]]
            pt.loc[bad, ["cost_E", "cost_H"]] = np.nan
            pt.loc[bad, "order"] = "failed"
            pt.loc[bad, "E_lt_H"] = False
            pt.insert(0, "design", label)
            pt["ratio_H_over_E"] = pt["cost_H"] / pt["cost_E"]
            if base is None:
                base = dict(zip(pt["pair"], pt["order"]))
            pt["order_changes"] = [o != base[p] and o != "failed" for p, o in zip(pt["pair"], pt["order"])]
            pairs.append(pt.rename(columns={"cost_E": "effort_E", "cost_H": "effort_H"}))
    pairs = pd.concat(pairs, ignore_index=True) if pairs else pd.DataFrame()
    return table, pairs, notes


def effort_section(ctx: Context) -> Section:
    if ctx.effort_tables is None:
        return Section("effort", [])
    table, pairs, notes = effort_sensitivity_tables(ctx)
    designs = list(dict.fromkeys(table["design"]))
    lines = ["## Sensitivity of effort to the motion design", "",
             f"Effort (J s, mean over {int(table['samples'].max()) if len(table) else 0} layout(s) per trial, seed "
             f"{ctx.args.seed}) for each design: approach legs of 5 and 2 cm at every grasp and place, none (a "
             "clearance constraint keeps the carried block above the table and out of every other block and the bucket; "
             "docs/effort.md), and the run's design at twice its slices per phase. The first design is the run's. "
             "The legs designs have no obstacle constraint between their waypoints: 5 cm legs clear every solid, "
             "2 cm legs do not (blocks leaving the bucket pass into its 4.5 cm wall; depths in docs/effort.md), so "
             "compare 2 cm on pair 12 with care.",
             ""]
    if len(table):
        wide = table.pivot(index="trial", columns="design", values="effort").reindex([t.id for t in ctx.trials])[designs]
        lines += markdown(wide.reset_index())
        lines.append("")
    if len(pairs):
        ratio = pairs.pivot(index="pair", columns="design", values="ratio_H_over_E")[designs]
        order = pairs.pivot(index="pair", columns="design", values="order")[designs]
        changes = pairs.groupby("pair")["order_changes"].any()
        shown = pd.DataFrame({"pair": ratio.index})
        for d in designs:
            shown[f"H/E {d}"] = [f"{r:.3g} ({o})" for r, o in zip(ratio[d], order[d])]
        shown["order changes"] = ["yes" if changes[p] else "no" for p in ratio.index]
        lines += ["H/E effort ratio of every pair and its order under the tie rule (analysis.pairs.TIE_REL); "
                  "'order changes': some design orders the pair differently from the run's.", "",
                  *markdown(shown), ""]
    bad = table[table["not_converged"] > 0] if len(table) else table
    if len(bad):
        lines += ["Layouts whose KOMO solve ended feasible but without SNOPT's optimality certificate (info 41; "
                  "docs/effort.md): " + ", ".join(f"{r.trial} {r.design} ({r.not_converged})" for r in bad.itertuples())
                  + ".", ""]
    for note in notes:
        lines += [f"Failed: {note}", ""]
    lines += ["Tables: `effort_sensitivity.csv` (one row per design and trial), `effort_sensitivity_pairs.csv` "
              "(one row per design and pair).", ""]
    tables = {"effort_sensitivity": table} | ({"effort_sensitivity_pairs": pairs} if len(pairs) else {})
    return Section("effort", lines, tables)

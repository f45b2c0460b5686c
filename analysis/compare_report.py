"""The "model comparison" section of report.md and of the results page: in-sample
and out-of-sample scores side by side, the direct tests, the permutation tests,
how much the risk's Monte Carlo error widens the intervals, and the recovery
table of SIMULATED studies. Tables are built here once; the report writes them
as Markdown and the page as HTML."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.crossval import SCHEMES as PAPER_SCHEMES
from analysis.crossval import STRUCTURE_SCHEME
from analysis.data import ordered_datasets
from analysis.models import MODELS
from lgp.paper import PAPER_SIGMA

#: The schemes of the report's tables: the paper's three and folds by structure (issue 32).
SCHEMES = PAPER_SCHEMES + (STRUCTURE_SCHEME,)
#: Short names of the schemes in table headers.
SHORT = {"in-sample": "in-sample", "leave-one-pair-out": "held-out pairs", "leave-one-trial-out": "held-out trials",
         STRUCTURE_SCHEME: "held-out structures"}

CANNOT_FAIL = ("In sample the comparison of Eq. 1 with effort-only cannot fail: Eq. 1 nests effort-only "
               "(E = E(1-R) + E R, so effort-only is Eq. 1 with b1 = b2) and its sigma is chosen on the same data, so "
               "its in-sample r is at least effort-only's in every resample and the in-sample direct bootstrap test of "
               "full vs effort gives p = 0 whatever the data. Only the out-of-sample scores (held-out pairs: both "
               "trials of a pair predicted by a fit that never saw them, sigma chosen inside each fold) can come out "
               "either way.")


def side_by_side(comparison: pd.DataFrame) -> pd.DataFrame:
    """One row per (dataset, model): r with its 95% interval and RMSE under each
    scheme, and the pairs ordered E < H (analysis.pairs tie rule)."""
    rows = []
    for dataset in ordered_datasets(comparison["dataset"].unique()):
        for model in [m for m in comparison["model"].unique()]:
            g = comparison[(comparison["dataset"] == dataset) & (comparison["model"] == model)].set_index("scheme")
            row = {"dataset": dataset, "model": model}
            for s in SCHEMES:
                if s not in g.index:
                    continue
                x = g.loc[s]
                lo, hi = "r_low", "r_high"
                ci = f" [{x[lo]:.3f}, {x[hi]:.3f}]" if lo in x and np.isfinite(x[lo]) else ""
                row[f"r {SHORT[s]}"] = f"{x['r']:.3f}{ci}" if np.isfinite(x["r"]) else "n/a"
            for s in SCHEMES:
                if s in g.index:
                    row[f"RMSE {SHORT[s]}"] = round(float(g.loc[s, "rmse"]), 3)
            for s in SCHEMES:
                if s in g.index:
                    row[f"pairs E<H {SHORT[s]}"] = int(g.loc[s, "pairs_E_lt_H"])
            rows.append(row)
    return pd.DataFrame(rows)


def tests_table(tests: pd.DataFrame) -> pd.DataFrame:
    """Full vs effort-only per dataset: the direct bootstrap p in sample (on r)
    and out of sample (on held-out RMSE and r)."""
    rows = []
    t = tests[(tests["model_a"] == "full") & (tests["model_b"] == "effort")]
    for dataset in ordered_datasets(t["dataset"].unique()):
        g = t[t["dataset"] == dataset]
        row = {"dataset": dataset}
        for scheme in SCHEMES:
            for score in ("r", "rmse"):
                x = g[(g["scheme"] == scheme) & (g["score"] == score)]
                if len(x):
                    x = x.iloc[0]
                    row[f"{SHORT[scheme]} ({score})"] = f"{x['better'] or 'tie'} better, p = {x['p_value']:.3f}"
        rows.append(row)
    return pd.DataFrame(rows)


def permutation_table(perm: pd.DataFrame) -> pd.DataFrame:
    cols = ["kind", "calibration", "dataset", "observed_gain", "null_mean", "null_q95", "p_value", "n_perm",
            "distinct_assignments"]
    out = perm[[c for c in cols if c in perm]].copy()
    out["kind"] = out["kind"].map({"shuffle": "R shuffled across trials (NOT CALIBRATED)",
                                   "within-pair": "R swapped within pairs",
                                   "freedman-lane": "effort-only residuals permuted (Freedman-Lane)"})
    for c in ("observed_gain", "null_mean", "null_q95"):
        out[c] = out[c].round(4)
    out["p_value"] = out["p_value"].round(4)
    return out


def widening_text(comparison: pd.DataFrame) -> str:
    if "r_widening" not in comparison:
        return ("Risk was not redrawn in the bootstrap (the risk table gives no run counts), so the intervals hold "
                "participant sampling only.")
    parts = []
    for scheme in SCHEMES:
        w = comparison.loc[(comparison["scheme"] == scheme) & (comparison["model"] != "effort"), "r_widening"]
        w = w[np.isfinite(w)]
        if len(w):
            parts.append(f"{SHORT[scheme]} x{np.median(w):.2f} (range {w.min():.2f}-{w.max():.2f})")
    return ("Monte Carlo error of risk: every bootstrap resample also redraws each trial's risk from its runs "
            "(binomial with the table's run count, one uniform per trial for all sigmas). It widens the 95% intervals "
            "of r of the models that use risk by " + "; ".join(parts) + " (median over models and datasets; "
            "effort-only is unchanged; a trial with no falls in its runs redraws as 0).")


def recovery_table(summary: pd.DataFrame, paper_sigma: float = PAPER_SIGMA, source: str = "stated") -> pd.DataFrame:
    """At the grid sigma nearest `paper_sigma`: per true model and participants,
    the share of SIMULATED studies whose verdict is the true model under each
    procedure, and how often Eq. 1 beats effort-only out of sample."""
    s = summary[summary["source"] == source]
    if s.empty:
        return pd.DataFrame()
    sig = float(s["sigma"].unique()[np.argmin(np.abs(s["sigma"].unique() - paper_sigma))])
    at = s[np.isclose(s["sigma"], sig)]
    rows = []
    for model in MODELS:
        for n in sorted(at["participants"].unique()):
            g = at[(at["true_model"] == model) & (at["participants"] == n)].set_index("procedure")
            row = {"true model (SIMULATED)": model, "sigma": sig, "participants": int(n)}
            for proc in SCHEMES:
                if proc in g.index:
                    row[f"right verdict, {SHORT[proc]}"] = f"{100 * g.loc[proc, 'p_right']:.0f}%"
            if "leave-one-pair-out" in g.index:
                row["Eq. 1 beats effort, held-out pairs"] = f"{100 * g.loc['leave-one-pair-out', 'p_full_beats_effort']:.0f}%"
            rows.append(row)
    return pd.DataFrame(rows)


def comparison_lines(analysis: dict, markdown) -> list[str]:
    """report.md lines of the model comparison (needs run_analysis's comparison
    tables); `markdown` renders a DataFrame."""
    if "model_comparison" not in analysis:
        return []
    lines = ["## Model comparison: in-sample and out of sample", "", CANNOT_FAIL, "",
             "r (95% bootstrap interval centred on r: participants and risk runs resampled, the cross-validation redone "
             "in each resample; every interval in model_comparison.csv is centred on its point; the paper's percentile "
             "interval, which can miss r, is not reported), RMSE (z units) and pairs ordered E < H (tie rule of analysis.pairs):", "",
             markdown(side_by_side(analysis["model_comparison"])), "",
             "Direct bootstrap tests, Eq. 1 against effort-only (the paper's method, NOT CALIBRATED: shown to compare, "
             "not to decide):", "",
             markdown(tests_table(analysis["model_comparison_tests"])), "",
             widening_text(analysis["model_comparison"]), ""]
    if "noise_ceiling" in analysis:
        c = analysis["noise_ceiling"]
        lines += ["Noise ceiling beside the scores above (analysis.reliability): split-half reliability of the trial "
                  "means, Spearman-Brown corrected, and r_ceiling = sqrt(reliability), the r a model predicting the "
                  "true trial means would reach (95% interval centred on it, participants resampled):", "",
                  markdown(c[["dataset", "participants", "split_half_r", "reliability", "reliability_low",
                              "reliability_high", "r_ceiling", "r_ceiling_low", "r_ceiling_high"]].round(3)), ""]
    if "model_comparison_held_out_permutation" in analysis:
        perm = analysis["model_comparison_held_out_permutation"]
        lines += ["**The decision: the held-out comparison test (calibrated).** p of \"model_a predicts held-out "
                  "trials better than model_b\": the held-out RMSE difference on folds by structure against its "
                  "Freedman-Lane null (residuals of model_b's fit permuted, everything refit, sigma inside every "
                  "fold; analysis.crossval.permuted):", "",
                  markdown(perm[["dataset", "model_a", "model_b", "rmse_a", "rmse_b", "observed", "n_perm",
                                 "p_value"]].round(4)), ""]
    if "model_comparison_held_out_tests" in analysis:
        held = analysis["model_comparison_held_out_tests"]
        lines += ["Held-out comparison paired over folds (sign-flip of the per-fold squared-error differences, "
                  "NOT CALIBRATED: conservative for the richer model, anti-conservative for the simpler one; shown "
                  "to compare, not to decide), p of \"model_a predicts held-out trials better than model_b\":", "",
                  markdown(held.assign(p_value=held["p_value"].round(4), sse_a=held["sse_a"].round(4),
                                       sse_b=held["sse_b"].round(4))), ""]
    if "permutation_test" in analysis:
        lines += ["Permutation tests of the risk term (statistic: held-out RMSE of effort-only minus Eq. 1's on folds by "
                  "structure; everything refit including sigma; Freedman-Lane is the default null, shuffle is NOT "
                  "CALIBRATED). p = (1 + permutations with a gain at least the observed) "
                  "/ (1 + permutations); distinct_assignments counts the different risk tables the permutations can "
                  "make, so p cannot go much below its inverse (trials with the same risk curve, e.g. never falling, "
                  "swap to the same table):", "",
                  markdown(permutation_table(analysis["permutation_test"])), ""]
    return lines


def recovery_lines(summary: pd.DataFrame, confusion: pd.DataFrame, markdown, paper_sigma: float = PAPER_SIGMA) -> list[str]:
    """report.md lines of the recovery section (SIMULATED studies): one block per
    parameter source (stated, and fitted to each dataset when there are data)."""
    from analysis.recovery import recovery_markdown

    lines = ["## Model recovery on SIMULATED studies (not human data)", "",
             "Could a study of this design tell the models apart on our effort and risk tables? Studies are simulated "
             "from each model (analysis.recovery: per-participant noise, scale and offset as analysis.simulate) and "
             "compared as the analysis compares them. Tables: recovery/simulated_recovery.csv (confusion matrix), "
             "recovery/simulated_recovery_summary.csv; figure recovery/simulated_recovery.png.", ""]
    for source in summary["source"].unique():
        lines += [f"### Parameters {source}", ""] + recovery_markdown(summary, confusion, paper_sigma, source)
    return lines

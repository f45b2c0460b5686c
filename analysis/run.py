"""The Results section end to end: from human responses and the effort and risk
tables to fits, sigma profile, bootstrap, tests, pair table and figures."""
from __future__ import annotations

from lgp.atomic import write_csv_atomic

import os
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.crossval.permuted import HELD_OUT_STREAM, held_out_permutation_tests
from analysis.reliability import CEILING_STREAM, noise_ceiling
from analysis.crossval import (MIN_PAIRS, RISK_DRAW_STREAM, RISK_DRAWS, SCHEMES, STRUCTURE_SCHEME, bootstrap_comparison, comparison_tests,
                               gain_over_effort, grouping_label, held_out_tests, measure_grid, model_comparison, redraw_risk,
                               risk_grid, structure_groups, summarize_comparison)
from analysis.spec import HEURISTIC_MODELS
from analysis.permutation import N_PERM, PERMUTATION_STREAM, check_count, permutation_test
from analysis.bootstrap import COMPARISONS, bootstrap_model_correlations, bootstrap_tests, summarize_bootstrap
from analysis.data import (exclude_constant_participants, is_simulated, load_human_data, ordered_datasets,
                           resample_trial_means, trial_mean_intervals, validate_human_data,
                           zscore_responses)
from analysis.data.trialset import pair_numbers, trial_ids, using_trials
from analysis.figures import (plot_effort_risk, plot_model_comparison, plot_model_correlations, plot_sigma_profile,
                              plot_trial_means)
from analysis.models import (MEASURE_BASES, MODELS, RISK_MEASURES, effort_per_trial, fit_models,
                             measure_at_sigma, measure_model, risk_at_sigma, risk_inputs, risk_sigmas)
from analysis.pairs import pair_table
from analysis.sigma import PAPER_SIGMA, choose_sigma, sigma_profile
from lgp.errors import InputError


class AnalysisResult(dict):
    """What the analysis computed, nothing written yet: its tables by name (each
    written as ``<prefix><name>.csv`` by `write_analysis`), the figures to draw
    (plot function and its keyword arguments but the folder), the file prefix
    ("simulated_" for SIMULATED participants) and the trial set it ran on (None:
    the paper's 24).

    The tables:
    settings (one row: seed, n_boot, sigma used and why, z-score SD ...),
    orderings (dataset, source, pair, cost_E, cost_H, order, E_lt_H; source is
    effort, risk, human or a model name; dataset "all" for effort and risk, which
    do not depend on it; order under the tie rule of analysis.pairs.TIE_REL) and, with human data, excluded_participants,
    zscored, trial_means (mean_z with 95% CI), sigma_profile, sigma_choice,
    fits, predictions, bootstrap_correlations, bootstrap_summary,
    bootstrap_tests (these in-sample, column scheme "in-sample"); with
    `compare`, model_comparison (in-sample and out-of-sample scores of every
    model side by side, with bootstrap intervals), model_comparison_gain (RMSE
    below effort-only's, with intervals centred on their points; the paper's
    percentile interval, which can miss its point, is not reported),
    model_comparison_tests (direct bootstrap, the paper's method, labelled NOT
    CALIBRATED), model_comparison_held_out_permutation (the decision: the
    calibrated held-out comparison test, Freedman-Lane null on folds by
    structure, analysis.crossval.permuted), model_comparison_held_out_tests
    (sign-flip over folds, labelled NOT CALIBRATED), noise_ceiling (split-half
    reliability with Spearman-Brown and the r a model of the true trial means
    would reach, analysis.reliability), cv_predictions, cv_bootstrap,
    permutation_test and permutation_null.
    """

    def __init__(self, tables: dict, prefix: str = "", figures=(), trials=None):
        super().__init__(tables)
        self.prefix = prefix
        self.figures = list(figures)
        self.trials = None if trials is None else tuple(trials)


def run_analysis(human_df: pd.DataFrame | str | Path | None, effort_by_trial,
                 risk_table: pd.DataFrame, out_dir: str | Path, seed: int,
                 n_boot: int = 1000, jobs: int = 2, sigma: float | None = None,
                 sigmas=None, figures: bool = True, build_risk: pd.DataFrame | None = None,
                 risk_measure: str | None = None, compare: bool = True, n_perm: int = N_PERM,
                 risk_draw: str = "binomial", pair_names: dict | None = None,
                 features: pd.DataFrame | None = None, same=(), trials=None) -> dict[str, pd.DataFrame]:
    """Run the paper's analysis and write tidy CSVs and figures into `out_dir`.

    Parameters
    ----------
    human_df : validated or raw responses (columns dataset, participant, trial,
        response), a path to such a CSV (read with `load_human_data`, which
        refuses simulated datasets), or None for the model-only outputs.
        A DataFrame may hold simulated participants (`simulate_participants`);
        then every output file name starts with ``simulated_`` and figure
        titles say "SIMULATED participants (not human data)".
    effort_by_trial : effort per trial, e.g. columns trial, sample, effort
        (averaged over samples), or a Series indexed by trial id.
    risk_table : columns trial, sigma (units of block length d), risk; one row
        per (trial, sigma).
    out_dir : directory for CSVs and figures (created).
    seed : seeds the numpy Generator of the participant bootstrap.
    n_boot : bootstrap resamples per dataset (the paper used 1000).
    jobs : processes for the bootstrap refits; results do not depend on it.
    sigma : fix sigma (e.g. the paper's 0.065) instead of choosing the pooled
        least-mean-RMSE sigma. Without human data it defaults to 0.065 if the
        risk table has it, else the table's sigma nearest to 0.065.
    sigmas : sigmas for the RMSE profile (default: all in the risk table).
    figures : write figures (PNG and PDF) as well as CSVs.
    build_risk : optional aggregates of risk through the build, long form
        (trial, sigma, measure, risk; models.risk.build.measure_table). With
        human data, every measure m adds models full[m] and risk[m] (Eq. 1 and
        the risk lesion with m in place of R) to the fits, the bootstrap and the
        tests (full[m] against full). They are read at the table's sigma
        nearest the chosen sigma (settings: build_risk_sigma).
    risk_measure : one of final, max, expected, any, care: the plain models
        full and risk use that aggregate as R instead of the final-state risk
        table (needs `build_risk`). None: the paper's R.
    compare : with human data, also the out-of-sample comparison
        (analysis.crossval: leave-one-pair-out and leave-one-trial-out, sigma
        chosen inside each fold, the cross-validation redone in every bootstrap
        resample), the permutation tests of the risk term
        (analysis.permutation), the calibrated held-out comparison test of every
        comparison (analysis.crossval.permuted) and the noise ceiling
        (analysis.reliability).
    n_perm : permutations per permutation test (default 1000), a whole number >= 1.
    features : the heuristic predictors per trial (analysis.heuristics.trial_features).
        Given, every heuristic model of analysis.spec.HEURISTIC_MODELS (each
        predictor alone, effort + height, effort + stacked) joins the fits, the
        bootstrap, the comparison and its tests (full against effort + height and
        effort + stacked), fitted exactly like effort-only.
    same : sets of trial ids whose B is the same structure (lgp.reproduce passes
        analysis.heuristics.identical_targets of the trial files): folds by
        structure hold each set out together (with pairs and identical risk curves).
    risk_draw : "binomial" (default): every bootstrap resample of the comparison
        also redraws each trial's risk from its runs (run counts from the risk
        table's n_sims or n column); "none": risk fixed at the table. The
        comparison's intervals are reported both ways.

    trials : the trial ids of the run (default the paper's 24; analysis.data.trialset).
        The human data must name exactly these. Pair tables (orderings), the
        within-pair permutation null, leave-one-pair-out folds and the pair
        figures need easy/hard pairs (nE and nH both; MIN_PAIRS for the folds):
        on a set without them they are left out and the table ``skipped`` (what,
        reason) says why; the paper's set never has this table.
    Returns the tables of the AnalysisResult (see there), each also written as
    ``<key>.csv``, plus files (kind, path) listing everything written.
    """
    options = {k: v for k, v in locals().items() if k != "out_dir"}
    return write_analysis(compute_analysis(**options), out_dir)


def compute_analysis(human_df, effort_by_trial, risk_table: pd.DataFrame, seed: int, n_boot: int = 1000, jobs: int = 2,
                     sigma: float | None = None, sigmas=None, figures: bool = True, build_risk: pd.DataFrame | None = None,
                     risk_measure: str | None = None, compare: bool = True, n_perm: int = N_PERM,
                     risk_draw: str = "binomial", pair_names: dict | None = None, features: pd.DataFrame | None = None,
                     same=(), trials=None) -> AnalysisResult:
    """`run_analysis` without writing: the AnalysisResult (see run_analysis for the parameters)."""
    if trials is not None and tuple(str(t).strip().upper() for t in trials) != trial_ids():
        options = dict(locals())
        with using_trials(trials):
            result = compute_analysis(**{**options, "trials": None})
        result.trials = tuple(str(t).strip().upper() for t in trials)
        return result
    check_count(n_boot, "the number of bootstrap resamples")
    check_count(n_perm, "the number of permutations")
    if risk_draw not in RISK_DRAWS:
        raise InputError(f"unknown risk draw {risk_draw!r}; expected one of {', '.join(RISK_DRAWS)}")
    E = effort_per_trial(effort_by_trial)
    skipped = _skipped(compare)
    if human_df is None:
        result = _model_only(E, risk_table, seed, jobs, sigma, figures, pair_names)
    else:
        result = _with_responses(human_df, E, risk_table, seed=seed, n_boot=n_boot, jobs=jobs, sigma=sigma, sigmas=sigmas,
                                 figures=figures, build_risk=build_risk, risk_measure=risk_measure, compare=compare,
                                 n_perm=n_perm, risk_draw=risk_draw, pair_names=pair_names, features=features, same=same)
    if skipped is not None:
        result["skipped"] = skipped
    return result


def write_analysis(result: AnalysisResult, out_dir: str | Path) -> dict[str, pd.DataFrame]:
    """Write an AnalysisResult into `out_dir`: every table as ``<prefix><name>.csv``,
    every figure (PNG and PDF) and ``<prefix>files.csv`` listing them. Returns the
    tables with ``files`` (kind, path) added, as run_analysis always has."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with using_trials(result.trials) if result.trials is not None else nullcontext():
        figure_paths = [p for plot, options in result.figures for p in plot(**options, out_dir=out_dir)]
    return _write(dict(result), out_dir, result.prefix, figure_paths)


def _model_only(E: pd.Series, risk_table: pd.DataFrame, seed: int, jobs: int, sigma: float | None, figures: bool,
                pair_names) -> AnalysisResult:
    """Without human data: the effort and risk pair tables at the paper's sigma (or `sigma`) and the pair figure."""
    available = risk_sigmas(risk_table)
    if sigma is None:
        sigma = float(available[np.argmin(np.abs(available - PAPER_SIGMA))])
        rule = "paper's sigma (or nearest in risk table); no human data to fit"
    else:
        rule = "given by caller"
    results, plots = {}, []
    if pair_numbers():
        results["orderings"] = _model_pairs(E, risk_at_sigma(risk_table, sigma))
    results["settings"] = pd.DataFrame([{
        "human_data": False, "simulated": False, "seed": seed, "n_boot": 0, "jobs": jobs,
        "sigma": sigma, "sigma_rule": rule}])
    if figures and pair_numbers():
        plots.append((plot_effort_risk, dict(effort_by_trial=E, risk_table=risk_table, sigma=sigma, names=pair_names)))
    return AnalysisResult(results, "", plots)


def _with_responses(human_df, E: pd.Series, risk_table: pd.DataFrame, *, seed, n_boot, jobs, sigma, sigmas, figures,
                    build_risk, risk_measure, compare, n_perm, risk_draw, pair_names, features, same) -> AnalysisResult:
    """The fits, sigma profile, bootstrap, tests and (with `compare`) the out-of-sample comparison of responses."""
    if isinstance(human_df, (str, Path)):
        responses = load_human_data(human_df)
    else:
        responses = validate_human_data(human_df, allow_simulated=True)
    simulated = is_simulated(responses)
    prefix = "simulated_" if simulated else ""
    kept, excluded = exclude_constant_participants(responses)
    zscored = zscore_responses(kept, ddof=0)
    boot_means = resample_trial_means(zscored, n_boot, np.random.default_rng(seed))
    means = trial_mean_intervals(zscored, boot_means)
    profile = sigma_profile(means, E, risk_table, sigmas)
    choice = choose_sigma(profile)
    if sigma is None:
        sigma = float(choice.loc[choice["dataset"] == "pooled", "sigma"].iloc[0])
        rule = "pooled: least mean RMSE of Eq. 1 across datasets"
    else:
        rule = "given by caller"
    R = risk_at_sigma(risk_table, sigma)
    models, comparisons, build_sigma, inputs = _models(R, sigma, build_risk, risk_measure, features)
    fits, predictions = fit_models(means, E, inputs, sigma, models=models, features=features)
    boot = bootstrap_model_correlations(boot_means, E, inputs, models=models, jobs=jobs, features=features)
    counts = zscored.groupby("dataset")["participant"].nunique()
    results = {
        "settings": pd.DataFrame([{
            "human_data": not simulated, "simulated": simulated, "seed": seed, "n_boot": n_boot,
            "jobs": jobs, "sigma": sigma, "sigma_rule": rule, "zscore_sd": "population (ddof=0)",
            "risk_measure": risk_measure or "paper (final-state risk table)",
            "build_risk_sigma": build_sigma if build_sigma is not None else np.nan,
            "participants": "; ".join(f"{d}={n}" for d, n in counts.items()),
            "excluded": len(excluded)}]),
        "excluded_participants": excluded,
        "zscored": zscored.drop(columns=["line"], errors="ignore"),
        "trial_means": means,
        "sigma_profile": profile,
        "sigma_choice": choice,
        "fits": fits,
        "predictions": predictions,
        "bootstrap_correlations": boot,
        "bootstrap_summary": summarize_bootstrap(boot, fits),
        "bootstrap_tests": bootstrap_tests(boot, fits, comparisons),
        "orderings": _orderings(E, R, means, predictions, simulated),
    }
    if not pair_numbers():
        del results["orderings"]
    for key in ("fits", "bootstrap_summary", "bootstrap_tests"):
        results[key] = results[key].assign(scheme="in-sample")
    if compare:
        source_R = risk_grid(risk_table, sigmas) if risk_measure is None else measure_grid(build_risk, risk_measure)
        grids = {"R": source_R}
        if build_risk is not None:
            grids.update({m: measure_grid(build_risk, m) for m in RISK_MEASURES})
        in_sample = {"R": sigma if risk_measure is None else build_sigma}
        in_sample.update({m: build_sigma for m in RISK_MEASURES if build_sigma is not None})
        draw = risk_draw if source_R.runs is not None else "none"
        groups = structure_groups(trial_ids(), source_R.risk, same)
        results.update(_comparison(means, boot_means, E, grids, models, comparisons, in_sample, seed, n_perm, draw,
                                   _feature_vectors(features), groups))
        results["noise_ceiling"] = noise_ceiling(results["zscored"], np.random.default_rng([seed, CEILING_STREAM]))
        results["settings"] = results["settings"].assign(
            n_perm=n_perm, risk_draw=draw, cv_sigma_rule="chosen inside each fold: least mean training RMSE of Eq. 1",
            folds_by_structure=grouping_label(groups, trial_ids()))
    plots = _figures(results, E, risk_table, sigma, prefix, compare, pair_names) if figures else []
    return AnalysisResult(results, prefix, plots)


def _models(R, sigma: float, build_risk, risk_measure, features):
    """The models and comparisons of the fits, the build-risk table's sigma nearest
    `sigma` (None without one) and the risk inputs of the fits."""
    models, comparisons, build_sigma = list(MODELS), list(COMPARISONS), None
    if risk_measure is not None and risk_measure not in RISK_MEASURES:
        raise InputError(f"unknown risk measure {risk_measure!r}; expected one of {', '.join(RISK_MEASURES)}")
    if build_risk is not None:
        have = np.unique(np.round(build_risk["sigma"].astype(float), 9))
        build_sigma = float(have[np.argmin(np.abs(have - sigma))])
        if risk_measure is not None:
            R = measure_at_sigma(build_risk, build_sigma, risk_measure)
        inputs = risk_inputs(R, build_risk, build_sigma)
        models += [measure_model(b, m) for m in RISK_MEASURES for b in MEASURE_BASES]
        comparisons += [(measure_model("full", m), "full") for m in RISK_MEASURES]
    elif risk_measure is not None:
        raise InputError(f"risk measure {risk_measure!r} needs the build-risk table (build_risk=...)")
    else:
        inputs = R
    if features is not None:
        models += list(HEURISTIC_MODELS)
        comparisons += [("full", "effort+height"), ("full", "effort+stacked")]
    return models, comparisons, build_sigma, inputs


def _feature_vectors(features):
    """The heuristic predictors as vectors over the trials (None without features)."""
    if features is None:
        return None
    from analysis.models import feature_vector
    from analysis.spec import FEATURES

    return {f: feature_vector(features, f) for f in FEATURES}


def _orderings(E: pd.Series, R: pd.Series, means: pd.DataFrame, predictions: pd.DataFrame, simulated: bool) -> pd.DataFrame:
    """Pair tables of effort, risk, the responses and every fitted model, per dataset."""
    pairs = [_model_pairs(E, R)]
    for dataset, group in means.groupby("dataset", sort=True):
        pairs.append(pair_table(group.set_index("trial")["mean_z"]).assign(
            dataset=dataset, source="simulated" if simulated else "human"))
        for model, p in predictions[predictions["dataset"] == dataset].groupby("model", sort=False):
            pairs.append(pair_table(p.set_index("trial")["predicted"]).assign(
                dataset=dataset, source=model))
    return _tidy_pairs(pd.concat(pairs, ignore_index=True))


def _figures(results: dict, E: pd.Series, risk_table: pd.DataFrame, sigma: float, prefix: str, compare: bool,
             pair_names) -> list:
    """The figures of an analysis with responses, in the order they are listed: (plot, keyword arguments)."""
    full = results["fits"][results["fits"]["model"] == "full"].set_index("dataset")[["b0", "b1", "b2"]]
    plots = []
    if pair_numbers():
        plots.append((plot_trial_means, dict(means=results["trial_means"], predictions=results["predictions"],
                                             stem=f"{prefix}fig3_trial_means")))
    plots.append((plot_model_correlations, dict(summary=results["bootstrap_summary"],
                                                stem=f"{prefix}fig4_model_correlations")))
    plots.append((plot_sigma_profile, dict(profile=results["sigma_profile"], choice=results["sigma_choice"],
                                           stem=f"{prefix}sigma_profile")))
    if compare:
        plots.append((plot_model_comparison, dict(summary=results["model_comparison"], stem=f"{prefix}fig4_model_comparison",
                                                  gain=results["model_comparison_gain"])))
    if pair_numbers():
        plots.append((plot_effort_risk, dict(
            effort_by_trial=E, risk_table=risk_table, sigma=sigma,
            betas={d: tuple(full.loc[d]) for d in ordered_datasets(full.index)},  # the paper's order, as every figure
            stem=f"{prefix}effort_risk_pairs", names=pair_names)))
    return plots


def _skipped(compare: bool) -> pd.DataFrame | None:
    """What the run's trial set cannot have, and why (None for a set with all of it,
    e.g. the paper's 24): pair tables and pair figures without pairs, the
    within-pair null without pairs, leave-one-pair-out with fewer than MIN_PAIRS."""
    pairs = pair_numbers()
    rows = []
    if not pairs:
        why = (f"the {len(trial_ids())} trials hold no easy/hard pair (nE and nH both)")
        rows += [("orderings (pair tables)", why), ("figures fig3_trial_means and effort_risk_pairs", why)]
        if compare:
            rows.append(("permutation null within-pair", why))
    if compare and len(pairs) < MIN_PAIRS:
        rows.append(("leave-one-pair-out cross-validation",
                     f"needs at least {MIN_PAIRS} easy/hard pairs; the {len(trial_ids())} trials hold {len(pairs)}"))
    return pd.DataFrame(rows, columns=["what", "reason"]) if rows else None


def _comparison(means: pd.DataFrame, boot_means, E: pd.Series, grids, models, comparisons, in_sample, seed: int,
                n_perm: int, risk_draw: str, features=None, groups=None) -> dict[str, pd.DataFrame]:
    """The out-of-sample comparison and the permutation tests (analysis.crossval,
    analysis.permutation) on the same participant resamples as the in-sample
    bootstrap. Risk redraws and permutations come from their own streams,
    ``default_rng([seed, RISK_DRAW_STREAM])``, ``default_rng([seed, PERMUTATION_STREAM])``
    and, for the calibrated held-out comparison test, ``default_rng([seed, HELD_OUT_STREAM])``."""
    y = {d: g.set_index("trial")["mean_z"].reindex(list(trial_ids())).to_numpy()
         for d, g in means.groupby("dataset", sort=False)}
    schemes = tuple(s for s in SCHEMES if s != "leave-one-pair-out" or len(pair_numbers()) >= MIN_PAIRS) \
        + (STRUCTURE_SCHEME,)
    kw = {"features": features, "groups": groups}
    point, cv_pred = model_comparison(y, E, grids, models, schemes, in_sample, **kw)
    fixed = bootstrap_comparison(boot_means, E, grids, models, schemes, in_sample, **kw)
    n_boot = len(next(iter(boot_means.values())))
    if risk_draw == "binomial":
        draws = redraw_risk(grids["R"], n_boot, np.random.default_rng([seed, RISK_DRAW_STREAM]))
        boot = bootstrap_comparison(boot_means, E, grids, models, schemes, in_sample, risk_draws=draws, **kw)
        summary = summarize_comparison(point, boot, fixed)
        tests = comparison_tests(point, boot, comparisons, fixed)
        cv_boot = pd.concat([boot.assign(risk_draw="binomial"), fixed.assign(risk_draw="none")], ignore_index=True)
    else:
        summary = summarize_comparison(point, fixed)
        tests = comparison_tests(point, fixed, comparisons)
        cv_boot = fixed.assign(risk_draw="none")
    perm, null = permutation_test(y, E, grids["R"], n_perm, np.random.default_rng([seed, PERMUTATION_STREAM]),
                                  groups=groups)
    gain = gain_over_effort(point, boot if risk_draw == "binomial" else fixed)
    decision = held_out_permutation_tests(y, E.reindex(list(trial_ids())).to_numpy(), grids, comparisons, groups, n_perm,
                                          np.random.default_rng([seed, HELD_OUT_STREAM]), features=features)
    return {"model_comparison": summary, "model_comparison_gain": gain, "model_comparison_tests": tests,
            "model_comparison_held_out_permutation": decision,
            "model_comparison_held_out_tests": held_out_tests(cv_pred, comparisons),
            "cv_predictions": cv_pred,
            "cv_bootstrap": cv_boot, "permutation_test": perm, "permutation_null": null}


def _model_pairs(E: pd.Series, R: pd.Series) -> pd.DataFrame:
    """Pair tables of effort and risk alone (no human data needed)."""
    return _tidy_pairs(pd.concat([pair_table(E).assign(dataset="all", source="effort"),
                                  pair_table(R).assign(dataset="all", source="risk")],
                                 ignore_index=True))


def _tidy_pairs(table: pd.DataFrame) -> pd.DataFrame:
    return table[["dataset", "source", "pair", "cost_E", "cost_H", "order", "E_lt_H"]]


def _write(results: dict[str, pd.DataFrame], out_dir: Path, prefix: str,
           figure_paths: list[Path]) -> dict[str, pd.DataFrame]:
    written = []
    for key, table in results.items():
        path = out_dir / f"{prefix}{key}.csv"
        write_csv_atomic(table, path)
        written.append(("table", str(path)))
    written += [("figure", str(p)) for p in figure_paths]
    files_path = out_dir / f"{prefix}files.csv"
    written.append(("table", str(files_path)))
    results["files"] = pd.DataFrame(written, columns=["kind", "path"])
    # On disk each path is relative to the folder holding files.csv, so the list stays
    # true when the folder is copied, moved, or swapped in from a run's staging folder
    # (absolute paths named the staging folder, gone after the swap).
    write_csv_atomic(results["files"].assign(path=[os.path.relpath(p, out_dir) for p in results["files"]["path"]]),
                     files_path)
    return results

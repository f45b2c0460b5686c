"""Model recovery and power: could a study with this design tell Eq. 1, effort-only
and risk-only apart, on the project's own effort and risk tables?

    python -m analysis.recovery --results results --out results/recovery

Everything here is SIMULATED: every file is named ``simulated_*``, every figure
title says "SIMULATED participants", and nothing is written into a folder that
holds a human-data analysis.

For each true model (full, effort, risk), true sigma (every sigma of the risk
table, any grid) and number of participants (default 20, 60, 200), `n_studies`
studies (default 200) are simulated. Participant p answers trial i with

    response = offset_p + scale_p * (y_i + noise_sd * eps_pi)

as `analysis.simulate` draws them (scale_p = exp(0.5 N(0,1)), offset_p ~
N(0, 10), eps ~ N(0, 1)), where y is the true model's cost at that sigma: Eq. 1
with (b0, b1, b2), effort-only b0 + b1 E, or risk-only b0 + b1 R. Parameters are
stated (DEFAULT_BETAS; noise_sd = `noise` x the SD of y over the 24 trials, so
every cell has the same signal-to-noise ratio) or fitted to a human dataset (the
model's in-sample fit at the analysis's sigma, in z units, and noise_sd the root
mean over trials of the between-participant variance of the z-scores).

Each study's responses are z-scored per participant and averaged per trial, and
the three models are compared as the analysis compares them: in-sample (sigma by
the RMSE rule on all 24 trials), leave-one-pair-out and leave-one-trial-out
(sigma chosen inside each fold; analysis.crossval). The verdict is the model of
least RMSE, a tie (relative 1e-9) going to the model with fewer parameters
(crossval.verdicts). Reported: the confusion matrix (how often each model wins
when each is true) and the probability of the right verdict, and how often Eq.
1 beats effort-only when Eq. 1 is true and when effort-only is.
"""
from __future__ import annotations

from lgp.atomic import write_csv_atomic

import argparse
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.crossval import SCHEMES, RiskGrid, cross_validate, risk_grid, scores, verdicts
from analysis.models import MODELS, ModelInputError, effort_per_trial
from lgp.paper import PAPER_SIGMA

#: Stated parameters: risky effort costs 4x safe effort (as analysis.demo); the
#: lesions' slopes are positive. Only the shape of y matters after z-scoring.
DEFAULT_BETAS: dict[str, tuple[float, ...]] = {"full": (0.0, 1.0, 4.0), "effort": (0.0, 1.0), "risk": (0.0, 1.0)}
#: Per-participant noise SD as a multiple of the SD of the true cost over the 24
#: trials: a participant's responses then correlate about 0.7 with the truth.
NOISE = 1.0
PARTICIPANTS: tuple[int, ...] = (20, 60, 200)
N_STUDIES = 200
PROG = "python -m analysis.recovery"
SIMULATED_PREFIX = "simulated_"


def model_cost(model: str, betas: Sequence[float], E: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The latent cost y of the 24 trials under `model` with `betas`."""
    b = tuple(float(v) for v in betas)
    if model == "full":
        if len(b) != 3:
            raise ModelInputError(f"Eq. 1 takes (b0, b1, b2); got {len(b)} value(s)")
        return b[0] + b[1] * E * (1 - R) + b[2] * E * R
    if len(b) != 2:
        raise ModelInputError(f"the {model}-only model takes (b0, b1); got {len(b)} value(s)")
    if model == "effort":
        return b[0] + b[1] * E
    if model == "risk":
        return b[0] + b[1] * R
    raise ModelInputError(f"unknown model {model!r}; expected one of {', '.join(MODELS)}")


def simulate_trial_means(y: np.ndarray, n_participants: int, noise_sd: float, n_studies: int,
                         rng: np.random.Generator, scale_log_sd: float = 0.5, offset_sd: float = 10.0) -> np.ndarray:
    """(n_studies, T) mean z-scores of simulated studies of `n_participants` each.

    Draws scales (n_studies, n), offsets (n_studies, n), noise (n_studies, n, T)
    in that order: for one study, the draws (and the trial means) of
    `analysis.simulate.simulate_participants` for one dataset.
    """
    y = np.asarray(y, dtype=float)
    scale = np.exp(scale_log_sd * rng.standard_normal((n_studies, n_participants)))
    offset = offset_sd * rng.standard_normal((n_studies, n_participants))
    noise = noise_sd * rng.standard_normal((n_studies, n_participants, len(y)))
    responses = offset[..., None] + scale[..., None] * (y + noise)
    z = (responses - responses.mean(axis=-1, keepdims=True)) / responses.std(axis=-1, keepdims=True)
    return z.mean(axis=1)


def fitted_parameters(zscored: pd.DataFrame, effort, grid: RiskGrid, sigma: float) -> dict[str, dict]:
    """Per dataset of a z-scored human (or simulated) table: each model's
    in-sample coefficients at `sigma` and the noise SD (z units), as
    {dataset: {"betas": {model: tuple}, "noise_sd": float}}."""
    from analysis.data import participant_matrices

    E = effort_per_trial(effort).to_numpy()
    k = int(np.argmin(np.abs(grid.sigmas - sigma)))
    R = grid.risk[k]
    designs = {"full": np.column_stack([np.ones(24), E * (1 - R), E * R]),
               "effort": np.column_stack([np.ones(24), E]), "risk": np.column_stack([np.ones(24), R])}
    out = {}
    for dataset, (_, Z) in participant_matrices(zscored).items():
        y = Z.mean(axis=0)
        betas = {m: tuple(float(v) for v in np.linalg.lstsq(X, y, rcond=None)[0]) for m, X in designs.items()}
        noise = float(np.sqrt(np.mean(Z.var(axis=0, ddof=1)))) if Z.shape[0] > 1 else 0.0
        out[dataset] = {"betas": betas, "noise_sd": noise}
    return out


def _cell(task) -> dict:
    """One (source, true model, sigma, participants) cell: verdict counts per procedure."""
    (source, model, betas, noise, noise_is_ratio, k_sigma, n, n_studies, seed_key, E, risk, procedures) = task
    y = model_cost(model, betas, E, risk[k_sigma])
    spread = float(np.std(y))
    out = {"source": source, "true_model": model, "sigma_index": k_sigma, "participants": n,
           "n_studies": n_studies, "noise_sd": noise * spread if noise_is_ratio else noise}
    if spread <= 1e-12 * max(1.0, float(np.max(np.abs(y)))):
        out["skipped"] = f"the {model} model's cost is the same on every trial at this sigma"
        return out
    rng = np.random.default_rng(seed_key)
    Y = simulate_trial_means(y, n, out["noise_sd"], n_studies, rng)[:, None, :]
    for proc in procedures:
        preds, _, _ = cross_validate(Y, E, {"R": risk}, list(MODELS), proc)
        rmse = {m: scores(Y, preds[m])["rmse"][:, 0] for m in MODELS}
        out[proc] = {"chosen": verdicts(rmse),
                     "full_beats_effort": verdicts({"effort": rmse["effort"], "full": rmse["full"]}) == "full"}
    return out


def recovery(effort, grid: RiskGrid, *, participants: Sequence[int] = PARTICIPANTS, n_studies: int = N_STUDIES,
             sigmas: Sequence[float] | None = None, betas: Mapping[str, Sequence[float]] | None = None,
             noise: float = NOISE, fitted: Mapping[str, dict] | None = None, seed: int = 0,
             procedures: Sequence[str] = SCHEMES, jobs: int = 1, executor=None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Simulate and refit every cell (module docstring).

    `betas` {model: betas} overrides DEFAULT_BETAS (stated, source "stated");
    `fitted` (from `fitted_parameters`) adds one source per dataset ("fitted to
    <dataset>", absolute noise). `sigmas` defaults to every sigma of `grid`.
    Cell c draws from ``default_rng([seed, source, model, sigma, participants])``
    (indices), so the numbers do not depend on `jobs`.

    Returns (confusion, summary): confusion one row per (source, true_model,
    sigma, participants, procedure, chosen_model): count, n_studies, rate;
    summary one row per (source, true_model, sigma, participants, procedure):
    p_right, p_full_beats_effort, noise_sd, betas (and skipped, why a cell was not run).
    """
    from lgp.executor import borrowed

    E = effort_per_trial(effort).to_numpy()
    if sigmas is None:
        idx = list(range(len(grid.sigmas)))
    else:
        idx = []
        for s in sigmas:
            k = int(np.argmin(np.abs(grid.sigmas - s)))
            if abs(grid.sigmas[k] - s) > 1e-9:
                raise ModelInputError(f"risk table has no rows at sigma {s:g}; it has sigma "
                                      f"{', '.join(f'{v:g}' for v in grid.sigmas)}")
            idx.append(k)
    sources = [("stated", {**DEFAULT_BETAS, **(betas or {})}, noise, True)]
    for dataset, par in (fitted or {}).items():
        sources.append((f"fitted to {dataset}", par["betas"], par["noise_sd"], False))
    tasks = []
    for a, (source, bet, nz, ratio) in enumerate(sources):
        for b, model in enumerate(MODELS):
            for k in idx:
                for n in participants:
                    tasks.append((source, model, tuple(bet[model]), nz, ratio, k, int(n), int(n_studies),
                                  [int(seed), a, b, k, int(n)], E, grid.risk, tuple(procedures)))
    with borrowed(executor, jobs) as ex:
        cells = ex.map(_cell, tasks)
    conf, summ = [], []
    for task, cell in zip(tasks, cells):
        sigma = float(grid.sigmas[cell["sigma_index"]])
        key = (cell["source"], cell["true_model"], sigma, cell["participants"])
        for proc in procedures:
            if "skipped" in cell:
                summ.append(key + (proc, np.nan, np.nan, cell["noise_sd"], str(task[2]), cell["skipped"]))
                continue
            chosen = cell[proc]["chosen"]
            for m in MODELS:
                count = int(np.sum(chosen == m))
                conf.append(key + (proc, m, count, cell["n_studies"], count / cell["n_studies"]))
            summ.append(key + (proc, float(np.mean(chosen == cell["true_model"])),
                               float(np.mean(cell[proc]["full_beats_effort"])), cell["noise_sd"], str(task[2]), ""))
    cols = ["source", "true_model", "sigma", "participants"]
    confusion = pd.DataFrame(conf, columns=cols + ["procedure", "chosen_model", "count", "n_studies", "rate"])
    summary = pd.DataFrame(summ, columns=cols + ["procedure", "p_right", "p_full_beats_effort", "noise_sd", "betas",
                                                 "skipped"])
    summary.attrs["noise"] = noise
    return confusion, summary


def check_output_dir(out: Path) -> None:
    """Refuse a folder that holds a human-data analysis (its tables are not named simulated_*)."""
    settings = out / "settings.csv"
    if settings.is_file():
        try:
            human = bool(pd.read_csv(settings)["human_data"].iloc[0])
        except (KeyError, IndexError, ValueError):
            human = False
        if human:
            raise ModelInputError(f"{out} holds a human-data analysis; simulated recovery results are not written "
                                  "where human data go (choose another --out)")


def write_recovery(confusion: pd.DataFrame, summary: pd.DataFrame, out: str | Path, paper_sigma: float = PAPER_SIGMA,
                   figures: bool = True) -> list[Path]:
    """simulated_recovery.csv (confusion), simulated_recovery_summary.csv and the
    figure simulated_recovery.png/.pdf into `out`. Returns the paths."""
    from analysis.figures import plot_recovery

    out = Path(out)
    check_output_dir(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{SIMULATED_PREFIX}recovery.csv", out / f"{SIMULATED_PREFIX}recovery_summary.csv"]
    write_csv_atomic(confusion, paths[0])
    write_csv_atomic(summary, paths[1])
    if figures:
        n = int(confusion["n_studies"].max()) if len(confusion) else 0
        ratio = (f"noise {summary.attrs['noise']:g} x SD of the true cost, " if "noise" in summary.attrs else "")
        paths += plot_recovery(summary, out, paper_sigma=paper_sigma, stem=f"{SIMULATED_PREFIX}recovery",
                               note=f"parameters stated: {ratio}{n} studies per cell")
    return paths


def recovery_markdown(summary: pd.DataFrame, confusion: pd.DataFrame, paper_sigma: float = PAPER_SIGMA,
                      source: str = "stated") -> list[str]:
    """Report lines: the confusion matrix and the right-verdict table at the
    table's sigma nearest the paper's, and P(Eq. 1 beats effort-only) over sigma."""
    s = summary[(summary["source"] == source)]
    if s.empty:
        return []
    sig = float(s["sigma"].unique()[np.argmin(np.abs(s["sigma"].unique() - paper_sigma))])
    lines = [f"SIMULATED participants (not human data), parameters {source}; sigma = {sig:g} d unless stated; "
             f"{int(confusion['n_studies'].max()) if len(confusion) else 0} studies per cell.", "",
             "Probability of the right verdict (the true model has the least RMSE):", "",
             "| true model | participants | in-sample | leave-one-pair-out | leave-one-trial-out |", "|---|---|---|---|---|"]
    at = s[np.isclose(s["sigma"], sig)]
    for model in MODELS:
        for n in sorted(at["participants"].unique()):
            row = at[(at["true_model"] == model) & (at["participants"] == n)].set_index("procedure")["p_right"]
            lines.append(f"| {model} | {n} | " + " | ".join(_pct(row.get(p, np.nan)) for p in SCHEMES) + " |")
    lines += ["", "Confusion matrix, leave-one-pair-out (rows: true model; columns: share of studies won):", "",
              "| true model | participants | full | effort | risk |", "|---|---|---|---|---|"]
    c = confusion[(confusion["source"] == source) & np.isclose(confusion["sigma"], sig)
                  & (confusion["procedure"] == "leave-one-pair-out")]
    for model in MODELS:
        for n in sorted(c["participants"].unique()):
            row = c[(c["true_model"] == model) & (c["participants"] == n)].set_index("chosen_model")["rate"]
            lines.append(f"| {model} | {n} | " + " | ".join(_pct(row.get(m, np.nan)) for m in MODELS) + " |")
    lines += ["", "Eq. 1 beats effort-only out of sample (leave-one-pair-out RMSE), by true sigma: "
              "share of studies when Eq. 1 is true (power) / when effort-only is true (false alarms):", ""]
    ns = sorted(s["participants"].unique())
    lines += ["| sigma | " + " | ".join(f"n = {n}" for n in ns) + " |", "|---|" + "---|" * len(ns)]
    lo = s[s["procedure"] == "leave-one-pair-out"]
    for sg in sorted(lo["sigma"].unique()):
        cells = []
        for n in ns:
            f = lo[np.isclose(lo["sigma"], sg) & (lo["participants"] == n)].set_index("true_model")["p_full_beats_effort"]
            cells.append(f"{_pct(f.get('full', np.nan))} / {_pct(f.get('effort', np.nan))}")
        lines.append(f"| {sg:g} | " + " | ".join(cells) + " |")
    return lines + [""]


def _pct(v) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{100 * v:.0f}%"


def read_tables(results: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """effort_samples.csv and risk.csv of a `lgp.reproduce` run (analysis.simulate.read_results)."""
    from analysis.simulate import read_results

    return read_results(results)


def main(argv=None) -> int:
    from lgp import cli

    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--results", default="results", type=cli.input_dir,
                   help="output folder of python -m lgp.reproduce (effort_samples.csv, risk.csv)")
    p.add_argument("--out", default="results/recovery", type=cli.output_dir)
    p.add_argument("--studies", type=cli.positive_int, default=N_STUDIES, help="simulated studies per cell")
    p.add_argument("--participants", type=cli.positive_int, nargs="+", default=list(PARTICIPANTS))
    p.add_argument("--sigmas", type=cli.sigma, nargs="+", help="true sigmas (default: every sigma of risk.csv)")
    p.add_argument("--noise", type=float, default=NOISE,
                   help="per-participant noise SD / SD of the true cost over trials (default %(default)s)")
    p.add_argument("--betas-full", type=float, nargs=3, metavar=("B0", "B1", "B2"), default=DEFAULT_BETAS["full"])
    p.add_argument("--betas-effort", type=float, nargs=2, metavar=("B0", "B1"), default=DEFAULT_BETAS["effort"])
    p.add_argument("--betas-risk", type=float, nargs=2, metavar=("B0", "B1"), default=DEFAULT_BETAS["risk"])
    p.add_argument("--human-data", type=cli.input_file,
                   help="also simulate at the parameters fitted to each dataset of this CSV (docs/human-data.md)")
    p.add_argument("--sigma", type=cli.sigma, default=None,
                   help="with --human-data: the sigma of the fitted parameters (default: the RMSE rule's)")
    p.add_argument("--seed", type=cli.seed, default=0)
    cli.add_jobs_argument(p, 1, "worker processes (default 1)")
    args = p.parse_args(argv)
    args.jobs = cli.capped_jobs(args.jobs, p.prog, args.oversubscribe)
    if not (np.isfinite(args.noise) and args.noise > 0):
        p.error(f"--noise must be a finite number > 0, got {args.noise!r}")
    effort, risk = read_tables(Path(args.results))
    grid = risk_grid(risk)
    fitted = None
    if args.human_data:
        from analysis.data import exclude_constant_participants, load_human_data, trial_means, zscore_responses
        from analysis.sigma import pooled_sigma, sigma_profile

        zscored = zscore_responses(exclude_constant_participants(load_human_data(args.human_data))[0])
        sigma = args.sigma if args.sigma is not None else pooled_sigma(sigma_profile(trial_means(zscored), effort, risk))
        fitted = fitted_parameters(zscored, effort, grid, sigma)
    check_output_dir(Path(args.out))
    confusion, summary = recovery(effort, grid, participants=args.participants, n_studies=args.studies,
                                  sigmas=args.sigmas, noise=args.noise, fitted=fitted, seed=args.seed, jobs=args.jobs,
                                  betas={"full": args.betas_full, "effort": args.betas_effort, "risk": args.betas_risk})
    paths = write_recovery(confusion, summary, args.out)
    print("\n".join(recovery_markdown(summary, confusion)))
    print(f"SIMULATED model recovery written to {Path(args.out).resolve()} ({len(paths)} files)")
    return 0


if __name__ == "__main__":
    from lgp import cli

    raise SystemExit(cli.run_cli(main, prog=PROG))

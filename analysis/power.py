"""Power of the comparison: SIMULATED studies through the project's own model
comparison, on a set of trials' cached effort, risk and heuristic predictors.

    python -m analysis.power --out results/power                    # the paper's 24 trials
    python -m analysis.power --world effort-only "full:b2b1=3,sigma=0.15" effort+height noise --studies 200

Everything here is SIMULATED: nothing stands in for human data. Every file is
named ``simulated_*``-free but lives in the --out folder with "SIMULATED" in its
columns and figure title.

A **world** is the true latent cost y of every trial (`World`):

* ``effort-only``: y = E (physical effort);
* ``full:b2b1=K,sigma=S``: Eq. 1 with b1 = 1, b2 = K, risk R at sigma S (a grid
  value of the risk table, units of d): y = E (1 - R) + K E R;
* ``effort+height`` / ``effort+stacked`` (optionally ``:w=W``): y = E / sd(E) +
  W h / sd(h), effort plus a no-physics heuristic of analysis.heuristics, equal
  weight on the standardised scale by default (W = 1);
* ``noise``: y = 0 on every trial, responses pure noise;
* ``csv:FILE``: y read from FILE (columns trial and mean, one row per trial).

A **study** has `participants` simulated participants; participant p answers
trial i with offset_p + scale_p (y_i + noise_sd eps_pi) (analysis.recovery's
draw: scale_p = exp(0.5 N(0,1)), offset_p ~ N(0, 10)); noise_sd = `noise` x
the SD of y over the trials (`noise` itself in the pure-noise world). Each
participant's responses are z-scored and averaged per trial, as the analysis does.

Each study is then analysed as the comparison analyses real data:

* **held-out verdict** (procedure ``held-out``): every model of MODELS (Eq. 1,
  effort-only, risk-only, each heuristic alone, effort + height, effort +
  stacked) scored by RMSE on folds by structure (crossval.STRUCTURE_SCHEME:
  trials whose B is identical, or that form a pair, are held out together),
  sigma chosen inside every fold; the verdict is the model of least held-out
  RMSE (ties, relative 1e-9, to the model with fewer parameters). Also each
  pairwise held-out preference of COMPARISONS (``held-out a vs b``).
* **tests** of "model a predicts held-out trials better than model b" at alpha,
  for each (a, b) of COMPARISONS (TESTS), rejecting at p <= alpha:
  - ``freedman-lane`` (the default, calibrated): the statistic is held-out
    RMSE(b) - RMSE(a); its null permutes the residuals of b's in-sample fit
    across trials and adds them back to b's fit (Freedman & Lane 1983), each
    permuted data set cross-validated whole (sigma inside folds);
    p = (1 + #{null >= observed}) / (1 + n_perm);
  - ``sign-flip`` (held-out, paired over folds): the per-fold difference of
    squared held-out error, SSE_b - SSE_a, its sum against all 2^F sign flips
    (exact); p = #{flipped sum >= observed} / 2^F;
  - ``within-pair`` (full vs effort only): each pair's easy and hard trial swap
    risk curves with probability 1/2 (analysis.permutation);
  - ``shuffle`` (full vs effort only; NOT CALIBRATED, kept to measure it): risk
    curves permuted across all trials;
  - ``direct-bootstrap`` (the paper's direct bootstrap test on held-out RMSE;
    BIASED toward the simpler model, kept to measure it): participants
    resampled with replacement, p = fraction of resamples in which the model
    better on the study is not strictly better; "a beats b" when a is better
    on the study and p <= alpha.

`power()` returns one row per (world, procedure, verdict): count, n_studies,
rate and its Wilson 95% interval (the Monte Carlo error of the rate).
Study s of world w draws everything from ``default_rng([seed, w, s])``, so the
numbers do not depend on how studies are spread over processes.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from analysis.power_tests import (ALPHA, CHUNK, COMPARISONS, DEFAULT_TESTS, MODELS, N_BOOT, N_PERM,  # noqa: F401
                                  RISK_ONLY_TESTS, TEST_LABELS, TESTS, TIE_REL, _cv, analyse_studies,
                                  direct_bootstrap_p, freedman_lane_p, freedman_lane_ps, heldout_scores,
                                  risk_permutation_p, sign_flip_p)
from analysis.power_worlds import (WORLD_KINDS, PowerInputError, TrialTable, World, _sigma_index,  # noqa: F401
                                   check_settings, parse_world, simulate_responses, trial_table)
from analysis.spec import FEATURES  # noqa: F401

PROG = "python -m analysis.power"
PARTICIPANTS = 60
NOISE = 1.0
N_STUDIES = 200
#: The default worlds of the CLI.
DEFAULT_WORLDS: tuple[str, ...] = ("effort-only", "full:b2b1=3,sigma=0.15", "full:b2b1=4,sigma=0.065",
                                   "effort+height", "effort+stacked", "noise")
#: Studies per work unit (a fixed number: the unit's studies seed themselves).
BLOCK = 25


def study_rngs(seed: int, world: int, studies: Sequence[int]) -> list[np.random.Generator]:
    """The Generator of each study: ``default_rng([seed, world, study])``."""
    return [np.random.default_rng([int(seed), int(world), int(s)]) for s in studies]


def _unit(task) -> pd.DataFrame:
    """One block of studies of one world (what executors map)."""
    (w, world, table, participants, noise, studies, seed, tests, comparisons, n_perm, n_boot) = task
    y = world.cost(table)
    noise_sd = noise if world.kind == "noise" else noise * float(np.std(y))
    if world.kind != "noise" and noise_sd <= 0:
        raise PowerInputError("--world", f"{world.label}: the true cost is the same on every trial")
    rngs = study_rngs(seed, w, studies)
    Z = [simulate_responses(y, participants, noise_sd, rng) for rng in rngs]
    df = analyse_studies(Z, table, rngs, tests, comparisons, n_perm, n_boot)
    df.insert(0, "study", list(studies))
    df.insert(0, "world", world.label)
    return df


def simulate_studies(table: TrialTable, worlds: Sequence[World | str], participants: int = PARTICIPANTS,
                     noise: float = NOISE, studies: int = N_STUDIES, seed: int = 0, executor=None, jobs: int = 1,
                     tests: Sequence[str] = DEFAULT_TESTS, comparisons=COMPARISONS, n_perm: int = N_PERM,
                     n_boot: int = N_BOOT, progress=None) -> pd.DataFrame:
    """Every SIMULATED study of every world, one row each (analyse_studies' columns,
    after world and study). Studies go to `executor` (lgp.executor; or a fresh one
    of `jobs`) in blocks of BLOCK."""
    from lgp.executor import borrowed

    worlds = [parse_world(w, table) if isinstance(w, str) else w for w in worlds]
    check_settings(participants, noise, studies, n_perm)
    for w in worlds:
        w.cost(table)
    tasks = [(k, w, table, int(participants), float(noise), tuple(range(lo, min(studies, lo + BLOCK))), int(seed),
              tuple(tests), tuple(comparisons), int(n_perm), int(n_boot))
             for k, w in enumerate(worlds) for lo in range(0, studies, BLOCK)]
    with borrowed(executor, jobs) as ex:
        parts = ex.map(_unit, tasks, progress)
    return pd.concat(parts, ignore_index=True)


def wilson(count, n, z: float = 1.959963984540054) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of count / n (95% by default)."""
    count, n = np.asarray(count, float), np.asarray(n, float)
    p = count / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    # exact at the ends (rounding would leave 1 - 1e-16 below a rate of 1)
    return np.where(count <= 0, 0.0, np.clip(centre - half, 0, 1)), np.where(count >= n, 1.0, np.clip(centre + half, 0, 1))


def summarize(per_study: pd.DataFrame, alpha: float = ALPHA, models: Sequence[str] = MODELS) -> pd.DataFrame:
    """The power table: one row per (world, procedure, verdict) with count,
    n_studies, rate, rate_low, rate_high (Wilson 95%), label SIMULATED.

    Procedures: ``held-out`` (verdict: the model picked, every model listed even
    at 0), ``held-out a vs b`` (verdict "a" or "b": the lower held-out RMSE, ties
    to b), and each test "<test> a>b" (verdicts "a beats b (p <= alpha)" and "not
    significant"; a permutation p = (1 + k) / (1 + P) <= alpha has probability at
    most alpha under the null).
    """
    rows = []
    for world, g in per_study.groupby("world", sort=False):
        n = len(g)
        picks = g["held-out"].to_numpy()
        for m in models:
            rows.append((world, "held-out", m, int(np.sum(picks == m)), n))
        for a, b in COMPARISONS:
            if f"rmse:{a}" in g and f"rmse:{b}" in g:
                wins = int(np.sum(g[f"rmse:{a}"].to_numpy() < g[f"rmse:{b}"].to_numpy()))
                rows.append((world, f"held-out {a} vs {b}", a, wins, n))
                rows.append((world, f"held-out {a} vs {b}", b, n - wins, n))
        for col in [c for c in g.columns if c.startswith("p:")]:
            _, test, ab = col.split(":", 2)
            a, b = ab.split(">")
            k = int(np.sum(g[col].to_numpy() <= alpha))
            rows.append((world, f"{test} {a}>{b}", f"{a} beats {b} (p <= {alpha:g})", k, n))
            rows.append((world, f"{test} {a}>{b}", "not significant", n - k, n))
    out = pd.DataFrame(rows, columns=["world", "procedure", "verdict", "count", "n_studies"])
    out["rate"] = out["count"] / out["n_studies"]
    lo, hi = wilson(out["count"], out["n_studies"])
    out["rate_low"], out["rate_high"] = lo, hi
    out["data"] = "SIMULATED"
    return out


def power(table: TrialTable, worlds: Sequence[World | str], participants: int = PARTICIPANTS, noise: float = NOISE,
          studies: int = N_STUDIES, seed: int = 0, executor=None, jobs: int = 1, tests: Sequence[str] = DEFAULT_TESTS,
          n_perm: int = N_PERM, n_boot: int = N_BOOT, alpha: float = ALPHA, progress=None) -> pd.DataFrame:
    """The power table (`summarize`) of SIMULATED studies (`simulate_studies`);
    the per-study table is kept in ``.attrs["studies"]``. `progress(k, block)` is
    called as each block of studies arrives."""
    per = simulate_studies(table, worlds, participants, noise, studies, seed, executor, jobs, tests,
                           n_perm=n_perm, n_boot=n_boot, progress=progress)
    out = summarize(per, alpha)
    out.attrs["studies"] = per
    out.attrs["grouping"] = table.grouping
    return out


# ----------------------------------------------------------------------------- inputs and CLI

def load_trial_table(stimuli_dir: str | Path | None = None, cache_dir: str | Path = "results/cache",
                     samples: int | None = None, n_sims: int | None = None, sigmas: Sequence[float] | None = None,
                     seed: int = 0, executor=None, jobs: int = 1) -> TrialTable:
    """Effort, risk and heuristics of the trials of `stimuli_dir` (default the
    paper's 24), through lgp.reproduce's stages and cache in `cache_dir`: cached
    trials are read, missing ones computed (and cached) as lgp.reproduce would.
    Defaults: the paper's M and N, the wide sigma grid (0.05..0.30 d)."""
    import stimuli
    from lgp.app.cache import Cache
    from lgp.app.stages import effort_tables, risk_tables
    from lgp.executor import borrowed
    from lgp.paper import N_SIMS, SAMPLES, WIDE_SIGMA_GRID
    from analysis.heuristics import identical_targets, trial_features

    samples = SAMPLES if samples is None else samples
    n_sims = N_SIMS if n_sims is None else n_sims
    sigmas = WIDE_SIGMA_GRID if sigmas is None else tuple(sigmas)
    trials = stimuli.load_paper() if stimuli_dir is None else stimuli.load_all(stimuli_dir)
    cache = Cache(cache_dir)
    with borrowed(executor, jobs) as ex:
        effort = effort_tables(trials, samples, seed, ex, cache, verbose=False)
        risk = risk_tables(trials, sigmas, n_sims, seed, None, ex, cache, verbose=False)
    features = trial_features(trials, samples, seed)
    return trial_table(effort, risk, features, [t.id for t in trials], identical_targets(trials))


def read_trial_table(results: str | Path, stimuli_dir: str | Path | None = None, samples: int = 30,
                     seed: int = 0) -> TrialTable:
    """A TrialTable from a finished `lgp.reproduce` run's effort_samples.csv and
    risk.csv in `results` (no physics), the heuristics from the trial files of
    `stimuli_dir` (default the paper's) at the run's M and seed. Raises
    PowerInputError naming --results for a missing or unreadable table."""
    import stimuli
    from analysis.heuristics import identical_targets, trial_features

    tables = []
    for name, columns in (("effort_samples.csv", ("trial", "effort")), ("risk.csv", ("trial", "sigma", "risk"))):
        path = Path(results) / name
        try:
            df = pd.read_csv(path, dtype={"trial": str})
        except (OSError, ValueError, UnicodeDecodeError) as e:
            raise PowerInputError("--results", f"{path}: cannot read ({type(e).__name__})") from None
        missing = [c for c in columns if c not in df.columns]
        if missing:
            raise PowerInputError("--results", f"{path}: missing column(s) {', '.join(missing)}")
        tables.append(df)
    trials = stimuli.load_paper() if stimuli_dir is None else stimuli.load_all(stimuli_dir)
    ids = [t.id for t in trials if t.id in set(tables[0]["trial"])]
    kept = [t for t in trials if t.id in ids]
    return trial_table(tables[0], tables[1], trial_features(kept, samples, seed), ids, identical_targets(kept))


def plot_confusion(table: pd.DataFrame, path: Path, models: Sequence[str] = MODELS, note: str = "") -> Path:
    """World x held-out verdict rates as a heatmap (SIMULATED in the title)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    held = table[table["procedure"] == "held-out"]
    worlds = list(dict.fromkeys(held["world"]))
    M = held.pivot_table(index="world", columns="verdict", values="rate", sort=False).reindex(index=worlds,
                                                                                              columns=list(models))
    n = int(held["n_studies"].iloc[0]) if len(held) else 0
    fig, ax = plt.subplots(figsize=(1.0 + 0.75 * len(models), 1.2 + 0.55 * len(worlds)))
    im = ax.imshow(M.to_numpy(float), cmap="Blues", vmin=0, vmax=1, aspect="auto")
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            v = M.iat[i, j]
            ax.text(j, i, f"{100 * v:.0f}", ha="center", va="center", fontsize=8,
                    color="white" if v > 0.6 else "black")
    ax.set_xticks(range(len(models)), models, rotation=40, ha="right", fontsize=8)
    ax.set_yticks(range(len(worlds)), worlds, fontsize=8)
    ax.set_xlabel("model picked by held-out RMSE (folds by structure)")
    ax.set_ylabel("true world")
    ax.set_title(f"SIMULATED studies (not human data): % of {n} studies per world" + (f"; {note}" if note else ""),
                 fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.03, label="rate")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def _precheck(worlds: Sequence[World], stimuli_dir, results=None) -> None:
    """Before any physics: every full world's sigma on the grid load_trial_table uses
    (or --results' risk.csv has), every csv world's trials among the trial files."""
    import stimuli
    from lgp.paper import WIDE_SIGMA_GRID

    grid = np.asarray(WIDE_SIGMA_GRID, float)
    if results is not None:
        try:
            grid = np.unique(np.round(pd.read_csv(Path(results) / "risk.csv", usecols=["sigma"])["sigma"].to_numpy(float), 9))
        except (OSError, ValueError) as e:
            raise PowerInputError("--results", f"{Path(results) / 'risk.csv'}: cannot read ({type(e).__name__})") from None
    ids = [t.id for t in (stimuli.load_paper() if stimuli_dir is None else stimuli.load_all(stimuli_dir))]
    for w in worlds:
        if w.kind == "full":
            _sigma_index(grid, w.sigma)
        if w.kind == "csv":
            unknown = [t for t, _ in w.means if t not in ids]
            if unknown:
                raise PowerInputError("--world", f"csv:{w.source} names unknown trial {unknown[0]}")


def main(argv=None) -> int:
    import sys
    import time

    from lgp import cli
    from lgp.atomic import write_csv_atomic
    from lgp.executor import executor_for_scheduler

    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--stimuli", metavar="DIR", type=cli.input_dir, help="trial files (default: the paper's 24)")
    p.add_argument("--cache", default="results/cache", help="lgp.reproduce's cache folder (default %(default)s)")
    p.add_argument("--results", metavar="DIR", type=cli.input_dir,
                   help="instead of the cache: a finished lgp.reproduce run's effort_samples.csv and risk.csv")
    p.add_argument("--participants", type=int, default=PARTICIPANTS, help="per simulated study (>= 2; default %(default)s)")
    p.add_argument("--noise", type=float, default=NOISE,
                   help="per-participant noise SD / SD of the true cost over trials (default %(default)s)")
    p.add_argument("--world", nargs="+", default=list(DEFAULT_WORLDS),
                   help="worlds: effort-only, full:b2b1=K,sigma=S, effort+height[:w=W], effort+stacked[:w=W], noise, "
                        "csv:FILE (default: %(default)s)")
    p.add_argument("--studies", type=int, default=N_STUDIES, help="simulated studies per world (default %(default)s)")
    p.add_argument("--tests", nargs="+", default=list(DEFAULT_TESTS), help=f"of {', '.join(TESTS)} (default %(default)s)")
    p.add_argument("--n-perm", type=int, default=N_PERM, help="permutations per permutation test (default %(default)s)")
    p.add_argument("--n-boot", type=int, default=N_BOOT, help="resamples of the direct bootstrap (default %(default)s)")
    p.add_argument("--samples", type=cli.positive_int, help="M layouts of A (default the paper's 30)")
    p.add_argument("--n-sims", type=cli.positive_int, help="N noisy runs per trial and sigma (default the paper's 100)")
    p.add_argument("--seed", type=cli.seed, default=0)
    p.add_argument("--jobs", type=cli.positive_int, default=2)
    p.add_argument("--scheduler", help="tcp://HOST:8786 or local-dask, as lgp.reproduce (docs/scaling.md)")
    p.add_argument("--out", default="results/power", type=cli.output_dir)
    args = p.parse_args(argv)
    from lgp.owned import ForeignFiles, csv_record, refuse_foreign_folder

    try:
        check_settings(args.participants, args.noise, args.studies, args.n_perm)
        if args.n_boot < 1:
            raise PowerInputError("--n-boot", f"must be a whole number >= 1, got {args.n_boot}")
        for t in args.tests:
            if t not in TESTS:
                raise PowerInputError("--tests", f"unknown test {t!r}; expected one of {', '.join(TESTS)}")
        worlds = [parse_world(w) for w in args.world]
        _precheck(worlds, args.stimuli, args.results)
        refuse_foreign_folder(Path(args.out), "power.csv", is_ours=csv_record("world", "procedure", "verdict", "count", "n_studies"))  # before the simulated studies, not after
        t0 = time.perf_counter()
        with executor_for_scheduler(args.scheduler, args.jobs) as ex:
            if args.results:
                table = read_trial_table(args.results, args.stimuli, args.samples or 30, args.seed)
            else:
                table = load_trial_table(args.stimuli, args.cache, args.samples, args.n_sims, seed=args.seed, executor=ex)
            worlds = [parse_world(w, table) for w in args.world]
            done = [0]
            total = len(worlds) * math.ceil(args.studies / BLOCK)

            def progress(k, _):
                done[0] += 1
                print(f"\r{PROG}: {done[0]}/{total} blocks of SIMULATED studies", end="", file=sys.stderr, flush=True)

            result = power(table, worlds, args.participants, args.noise, args.studies, args.seed, ex,
                           tests=args.tests, n_perm=args.n_perm, n_boot=args.n_boot, progress=progress)
            print(file=sys.stderr)
    except (PowerInputError, ForeignFiles) as e:
        p.exit(2, f"{PROG}: error: {e}\n")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv_atomic(result, out / "power.csv")
    write_csv_atomic(result.attrs["studies"], out / "power_studies.csv")
    plot_confusion(result, out / "power_confusion.png",
                   note=f"{args.participants} participants, noise {args.noise:g}")
    held = result[result["procedure"] == "held-out"].pivot_table(index="world", columns="verdict", values="rate",
                                                                  sort=False)
    print(f"SIMULATED studies: {args.studies} per world, {args.participants} participants, noise {args.noise:g}; "
          f"folds by structure: {table.grouping}")
    print((100 * held).round(0).to_string())
    print("\n".join(power_markdown(result)))
    print(f"written to {out.resolve()} (power.csv, power_studies.csv, power_confusion.png) in "
          f"{time.perf_counter() - t0:.0f} s")
    return 0



def power_markdown(table: pd.DataFrame) -> list[str]:
    """The docs' power table: per world, the held-out verdict's top picks and each
    test's rejection rate for full vs effort and full vs effort + height (percent,
    Wilson 95% interval), from `power`'s table."""
    def cell(world, proc, verdict):
        r = table[(table["world"] == world) & (table["procedure"] == proc) & (table["verdict"] == verdict)]
        if r.empty:
            return "n/a"
        r = r.iloc[0]
        return f"{100 * r['rate']:.0f}% [{100 * r['rate_low']:.0f}, {100 * r['rate_high']:.0f}]"

    cols = [("held-out picks full", "held-out", "full"), ("held-out picks effort", "held-out", "effort"),
            ("held-out picks effort+height", "held-out", "effort+height"),
            ("held-out picks effort+stacked", "held-out", "effort+stacked"),
            ("held-out: full < effort+height (RMSE)", "held-out full vs effort+height", "full"),
            ("Freedman-Lane: full beats effort", "freedman-lane full>effort", "full beats effort (p <= 0.05)"),
            ("Freedman-Lane: full beats effort+height", "freedman-lane full>effort+height",
             "full beats effort+height (p <= 0.05)"),
            ("Freedman-Lane: effort+height beats full", "freedman-lane effort+height>full",
             "effort+height beats full (p <= 0.05)"),
            ("sign-flip: full beats effort", "sign-flip full>effort", "full beats effort (p <= 0.05)"),
            ("sign-flip: full beats effort+height", "sign-flip full>effort+height", "full beats effort+height (p <= 0.05)"),
            ("sign-flip: effort+height beats full", "sign-flip effort+height>full", "effort+height beats full (p <= 0.05)")]
    worlds = list(dict.fromkeys(table["world"]))
    n = int(table["n_studies"].max()) if len(table) else 0
    lines = ["| SIMULATED world (truth) | " + " | ".join(c[0] for c in cols) + " |",
             "|---|" + "---|" * len(cols)]
    for w in worlds:
        lines.append(f"| {w} | " + " | ".join(cell(w, p, v) for _, p, v in cols) + " |")
    lines += ["", f"{n} SIMULATED studies per world; rates with their Wilson 95% interval (Monte Carlo error)."]
    return lines


if __name__ == "__main__":
    from lgp import cli

    raise SystemExit(cli.run_cli(main, prog=PROG))

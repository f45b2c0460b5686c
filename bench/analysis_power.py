"""Power and false-positive rates of the comparison on the paper's 24 trials
(analysis.power), all on SIMULATED studies, written as two sections of
docs/benchmarks.md and CSVs under --out:

    python bench/analysis_power.py --cache results/cache              # both parts
    python bench/analysis_power.py --only speed                       # the CLI's timing
    python bench/analysis_power.py --only fpr --fpr-studies 1000      # false-positive rates

* speed: ``python -m analysis.power --studies 200`` (six default worlds, default
  tests, --jobs 2) in a fresh subprocess, its wall time against the issue's goal
  (5 minutes on 2 cores), with the load average before and after; its
  power.csv is kept (the docs' power table is read from it).
* fpr: every test (analysis.power.TESTS: Freedman-Lane, sign-flip over folds,
  within-pair, shuffle, direct bootstrap) in the effort-only and pure-noise
  worlds, --fpr-studies studies each at n = 60, noise 1: the rate of p < .05
  with its Wilson 95% interval.

Effort, risk and heuristics come from lgp.reproduce's cache (--cache; the wide
sigma grid, M = 30, N = 100): cached trials are read, missing ones computed.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import machine, write_section  # noqa: E402


def _source(cache: str, results: str | None) -> list[str]:
    return ["--results", results] if results else ["--cache", cache]


def speed(cache: str, out: Path, studies: int, results: str | None = None, n_perm: int = 199) -> str:
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    c0 = os.times()
    cmd = [sys.executable, "-m", "analysis.power", "--studies", str(studies), "--jobs", "2", *_source(cache, results),
           "--n-perm", str(n_perm), "--out", str(out / "speed")]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    wall = time.perf_counter() - t0
    c1 = os.times()
    cpu = (c1.children_user + c1.children_system) - (c0.children_user + c0.children_system)
    load1 = os.getloadavg()
    if r.returncode != 0:
        raise SystemExit(f"analysis.power failed: {r.stderr.strip().splitlines()[-1:]}")
    verdict = "within" if wall <= 300 else "NOT within"
    return (f"`python -m analysis.power --studies {studies} --n-perm {n_perm} --jobs 2` (six default worlds, default "
            f"tests Freedman-Lane and sign-flip): **{wall:.0f} s** wall, {verdict} the goal of 5 minutes on 2 cores. "
            f"Load average before {load0[0]:.1f}, after {load1[0]:.1f} (1 min; other developers' "
            f"jobs share the 2 cores). Effort and risk read from {'--results ' + results if results else 'the cache'}.\n")


def fpr(cache: str, out: Path, studies: int, slow_studies: int, jobs: int, seed: int, n_perm: int, n_boot: int,
        results: str | None = None) -> tuple[str, pd.DataFrame]:
    """The cheap tests (Freedman-Lane, sign-flip) on `studies` studies per world; the
    costly ones (within-pair, shuffle: risk tables per permutation; direct bootstrap:
    a cross-validation per resample) on the first `slow_studies` of them (the same
    studies: study s seeds itself)."""
    from analysis import power as pw

    t0 = time.perf_counter()
    load0 = os.getloadavg()
    table = pw.read_trial_table(results) if results else pw.load_trial_table(None, cache, jobs=jobs)
    kw = dict(participants=60, noise=1.0, seed=seed, jobs=jobs, n_perm=n_perm, n_boot=n_boot)
    parts = []
    out.mkdir(parents=True, exist_ok=True)
    if studies:
        cheap = pw.power(table, ["effort-only", "noise"], studies=studies, tests=("freedman-lane", "sign-flip"), **kw)
        cheap.attrs = {}   # (the per-study table in attrs would make concat compare DataFrames)
        cheap.to_csv(out / "fpr_cheap.csv", index=False)
        parts.append(cheap)
    if slow_studies:
        costly = pw.power(table, ["effort-only", "noise"], studies=slow_studies,
                          tests=("within-pair", "shuffle", "direct-bootstrap"), **kw)
        costly.attrs = {}
        costly = costly[costly["procedure"].str.split(" ").str[0].isin(["within-pair", "shuffle", "direct-bootstrap"])]
        costly.to_csv(out / "fpr_costly.csv", index=False)
        parts.append(costly)
    res = pd.concat(parts, ignore_index=True)
    res.to_csv(out / "fpr.csv", index=False)
    sig = res[res["verdict"].str.contains("beats")]
    lines = [f"False-positive rates (p <= .05), SIMULATED studies (n = 60 participants, noise 1, {n_perm} "
             f"permutations, {n_boot} bootstrap resamples), seed {seed}: {studies} studies per world for "
             f"Freedman-Lane and sign-flip, the first {slow_studies} of them for the costly tests; "
             f"{time.perf_counter() - t0:.0f} s wall on --jobs {jobs}, load average {load0[0]:.1f} before, "
             f"{os.getloadavg()[0]:.1f} after. Folds by structure: {table.grouping}.", "",
             "| test | comparison | studies | effort-only world | pure-noise world |", "|---|---|---|---|---|"]
    for proc in dict.fromkeys(sig["procedure"]):
        test, ab = proc.split(" ", 1)
        cells = []
        for world in ("effort-only", "noise"):
            r = sig[(sig["procedure"] == proc) & (sig["world"] == world)].iloc[0]
            cells.append(f"{100 * r['rate']:.1f}% [{100 * r['rate_low']:.1f}, {100 * r['rate_high']:.1f}]")
        n = int(sig[sig["procedure"] == proc]["n_studies"].iloc[0])
        lines.append(f"| {pw.TEST_LABELS[test]} | {ab.replace('>', ' beats ')} | {n} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n", res


def intervals(cache: str, studies: int, n_boot: int, seed: int, results: str | None = None) -> str:
    """How often the paper's percentile interval misses its own point estimate, and
    how often the centred interval the outputs now carry does: SIMULATED studies
    (n = 60, noise 1) of two worlds, participants resampled n_boot times, the r of
    Eq. 1 and effort-only in sample (sigma fixed at the world's, as the paper did)
    and Eq. 1's held-out RMSE on folds by structure (sigma inside folds)."""
    import numpy as np

    from analysis import power as pw
    from analysis.bootstrap import centred_interval
    from analysis.models import rowwise_pearson

    t0, load0 = time.perf_counter(), os.getloadavg()
    table = pw.read_trial_table(results) if results else pw.load_trial_table(None, cache)
    k = int(np.argmin(np.abs(table.risk.sigmas - 0.15)))
    rows = []
    for w, world in enumerate(["effort-only", "full:b2b1=3,sigma=0.15"]):
        wd = pw.parse_world(world, table)
        y = wd.cost(table)
        miss = {key: [0, 0] for key in ("r full, in sample", "r effort, in sample", "RMSE full, held out")}
        for s, rng in enumerate(pw.study_rngs(seed, 100 + w, range(studies))):
            z = pw.simulate_responses(y, 60, float(np.std(y)), rng)
            Y = np.vstack([z.mean(axis=0), z[rng.integers(0, 60, size=(n_boot, 60))].mean(axis=1)])
            ins = pw._cv(Y, table, ["full", "effort"], "in-sample", risk=table.risk.risk[k:k + 1])
            held = pw._cv(Y, table, ["full"])["full"]
            values = {"r full, in sample": rowwise_pearson(ins["full"], Y),
                      "r effort, in sample": rowwise_pearson(ins["effort"], Y),
                      "RMSE full, held out": np.sqrt(np.mean((Y - held) ** 2, axis=1))}
            for key, v in values.items():
                lo, hi = np.percentile(v[1:], [2.5, 97.5])
                miss[key][0] += not (lo <= v[0] <= hi)
                c = centred_interval(v[0], v[1:])
                miss[key][1] += not (c[0] <= v[0] <= c[1])
        for key, (m_pct, m_cen) in miss.items():
            rows.append(f"| {wd.label} | {key} | {studies} | {100 * m_pct / studies:.1f}% | {100 * m_cen / studies:.1f}% |")
    return (f"How often a 95% bootstrap interval misses its own point estimate: SIMULATED studies (n = 60, noise 1), "
            f"{n_boot} participant resamples each, seed {seed}; {time.perf_counter() - t0:.0f} s wall, load average "
            f"{load0[0]:.1f} before, {os.getloadavg()[0]:.1f} after.\n\n"
            "| SIMULATED world | score | studies | paper's percentile interval misses the point | centred interval "
            "misses it |\n|---|---|---|---|---|\n" + "\n".join(rows) + "\n")


def predictors(results: str) -> str:
    """What the 24 trials can tell apart: each heuristic's correlation with effort, and
    the correlation of E*R beyond (1, E) with each heuristic beyond (1, E), by sigma."""
    import numpy as np

    from analysis import power as pw

    t = pw.read_trial_table(results)
    E, F = t.effort, t.features
    X = np.column_stack([np.ones(len(E)), E])

    def beyond(v):
        return v - X @ np.linalg.lstsq(X, v, rcond=None)[0]

    r = lambda a, b: float(np.corrcoef(a, b)[0, 1])  # noqa: E731
    lines = [f"Predictors of the paper's 24 trials ({results}): height equals depth on every trial: "
             f"{bool(np.array_equal(F['height'], F['depth']))}.", "",
             "| | " + " | ".join(F) + " |", "|---|" + "---|" * len(F),
             "| r with E | " + " | ".join(f"{r(E, v):.2f}" for v in F.values()) + " |"]
    for s in (0.065, 0.10, 0.15, 0.20):
        k = int(np.argmin(np.abs(t.risk.sigmas - s)))
        ER = E * t.risk.risk[k]
        lines.append(f"| r of E*R with it, both beyond (1, E), sigma {s:g} d | "
                     + " | ".join(f"{r(beyond(ER), beyond(v)):.2f}" for v in F.values()) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cache", default="results/cache")
    p.add_argument("--results", help="a finished lgp.reproduce run (effort_samples.csv, risk.csv) instead of the cache")
    p.add_argument("--out", default="results/bench_power")
    p.add_argument("--only", choices=["speed", "fpr", "predictors", "intervals"])
    p.add_argument("--interval-studies", type=int, default=200)
    p.add_argument("--studies", type=int, default=200)
    p.add_argument("--fpr-studies", type=int, default=1000)
    p.add_argument("--fpr-slow-studies", type=int, default=1000)
    p.add_argument("--n-perm", type=int, default=199)
    p.add_argument("--n-boot", type=int, default=200)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--docs", default=str(ROOT / "docs" / "benchmarks.md"))
    args = p.parse_args(argv)
    out = Path(args.out)
    if args.only in (None, "predictors"):
        if not args.results:
            raise SystemExit("--only predictors needs --results DIR")
        text = predictors(args.results)
        print(text)
        write_section(Path(args.docs), "analysis.power: what the 24 trials can tell apart",
                      f"## analysis.power: what the 24 trials can tell apart\n\n{text}")
    if args.only in (None, "intervals"):
        text = intervals(args.cache, args.interval_studies, args.n_boot, args.seed, args.results)
        print(text)
        write_section(Path(args.docs), "analysis: bootstrap intervals and their points",
                      f"## analysis: bootstrap intervals and their points\n\nMachine: {machine()}.\n\n{text}")
    if args.only in (None, "speed"):
        text = speed(args.cache, out, args.studies, args.results, args.n_perm)
        print(text)
        write_section(Path(args.docs), "analysis.power: speed",
                      f"## analysis.power: speed\n\nMachine: {machine()}.\n\n{text}")
    if args.only in (None, "fpr"):
        text, _ = fpr(args.cache, out, args.fpr_studies, args.fpr_slow_studies, args.jobs, args.seed, args.n_perm,
                      args.n_boot, args.results)
        print(text)
        write_section(Path(args.docs), "analysis.power: false-positive rates",
                      f"## analysis.power: false-positive rates\n\nMachine: {machine()}.\n\n{text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

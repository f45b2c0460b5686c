"""The stimulus designer's costs and its screen's faithfulness (docs/design.md).

    python bench/design.py [--candidates 400] [--engine-cache DIR ...] [--run DIR]

1. The screen's cost per candidate: candidates 0..C-1 of seed 0 through
   checks.screen_candidate in this process (one core), with the load noted;
   beside it, one MuJoCo stand check (sigma 0) and one noisy MuJoCo run of the
   same B's, so the ratio is measured side by side under the same load.
2. The screen against the faithful values on the paper's 24: the static risk
   curve vs the MuJoCo risk (runs read from the riskruns entries of an
   lgp.reproduce cache, --engine-cache, e.g. a ``--sigma-grid wide`` run's), and
   the effort proxy vs the planner's effort (the effort entries of that cache):
   Spearman rank correlations.
3. A design run's own timings (--run DIR: its design.json).

Prints markdown; writes the '## Stimulus design' section of docs/benchmarks.md with --write.
"""
from __future__ import annotations

import argparse
import glob
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy.stats import spearmanr  # noqa: E402

from bench.common import machine, write_section  # noqa: E402


def screen_cost(n: int) -> tuple[str, list]:
    from stimuli.design.checks import Discarded, screen_candidate
    from stimuli.design.grammar import draw

    screen_candidate(draw(1, 0), 10)  # imports, first numpy calls
    kept = []
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(n):
        c = draw(i, 0)
        try:
            screen_candidate(c, 10)
            kept.append(c)
        except Discarded:
            pass
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return f"| screen (checks + static MC, 9 sigmas x 100 runs) | {n} candidates | {wall / n * 1e3:.1f} ms | {cpu / n * 1e3:.1f} ms |", kept


def engine_cost(cands: list) -> list[str]:
    from models.risk import check_stable
    from models.risk.engine import get_engine
    from models.risk.noise import NoiseRule
    from stimuli.trial import parse_trial

    trials = [parse_trial(c.data) for c in cands]
    eng = get_engine("mujoco")
    t0, c0 = time.perf_counter(), time.process_time()
    for t in trials:
        try:
            check_stable(t.target)
        except ValueError:
            pass
    stand = ((time.perf_counter() - t0) / len(trials), (time.process_time() - c0) / len(trials))
    rng = np.random.default_rng(0)
    t0, c0 = time.perf_counter(), time.process_time()
    for t in trials:
        p = NoiseRule(t.target).positions(0.15, rng.standard_normal((len(t.target), 3)))
        eng.simulate(t.target, p_WB=p)
    run = ((time.perf_counter() - t0) / len(trials), (time.process_time() - c0) / len(trials))
    return [f"| MuJoCo stand check (sigma 0) | {len(trials)} of them | {stand[0] * 1e3:.1f} ms | {stand[1] * 1e3:.1f} ms |",
            f"| one noisy MuJoCo run (sigma 0.15 d, default noise rule) | {len(trials)} of them | {run[0] * 1e3:.1f} ms | {run[1] * 1e3:.1f} ms |"]


def paper_check(caches: list[str]) -> list[str]:
    import stimuli
    from stimuli.design.checks import features
    from stimuli.design.screen import PRIOR_GRID

    runs = [pd.read_csv(f, skiprows=1) for c in caches for f in glob.glob(f"{c}/riskruns-*.csv")]
    eff = [pd.read_csv(f, skiprows=1) for c in caches for f in glob.glob(f"{c}/effort-*.csv")]
    feat = pd.DataFrame([features(t, PRIOR_GRID, 100, 0) for t in stimuli.load_paper()]).set_index("trial")
    lines = ["| quantity | trials | Spearman rho (screen vs faithful) | Pearson r |", "|---|---|---|---|"]
    if runs:
        r = pd.concat(runs).drop_duplicates(["trial", "sigma", "run"]).groupby(["trial", "sigma"])["fell"].mean().unstack()
        r = r[[s for s in PRIOR_GRID if s in r.columns]]
        for s in r.columns:
            e, sc = r[s], feat.loc[r.index, f"screen_risk_{s:g}"]
            rho = spearmanr(e, sc).statistic if e.nunique() > 1 and sc.nunique() > 1 else float("nan")
            pr = np.corrcoef(e, sc)[0, 1] if e.nunique() > 1 and sc.nunique() > 1 else float("nan")
            lines.append(f"| risk at sigma {s:g} d (MuJoCo, N = {int(pd.concat(runs)['run'].max()) + 1}) | {len(r)} | {rho:.3f} | {pr:.3f} |")
        ep, sp = r.mean(axis=1), feat.loc[r.index, "screen_risk_prior"]
        lines.append(f"| risk, mean over the prior grid | {len(r)} | {spearmanr(ep, sp).statistic:.3f} | {np.corrcoef(ep, sp)[0, 1]:.3f} |")
    if eff:
        e = pd.concat(eff).drop_duplicates(["trial", "sample"]).groupby("trial")["effort"].mean()
        for col, what in (("effort_proxy", "effort proxy: assignment distance, 1 layout"),
                          ("path_squared", "rejected: sum of squared paths with approach legs"),
                          ("moved", "rejected: blocks moved")):
            x = feat.loc[e.index, col].astype(float)
            lines.append(f"| {what} vs planner effort (M = 30) | {len(e)} | {spearmanr(e, x).statistic:.3f} | {np.corrcoef(e, x)[0, 1]:.3f} |")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--candidates", type=int, default=400)
    p.add_argument("--engine-cache", nargs="*", default=[], help="lgp.reproduce cache folders holding the paper's 24")
    p.add_argument("--run", help="a design run's folder (its design.json)")
    p.add_argument("--write", action="store_true", help="write the section of docs/benchmarks.md")
    args = p.parse_args(argv)
    before = machine()
    row, kept = screen_cost(args.candidates)
    lines = ["## Stimulus design", "", f"`python bench/design.py --candidates {args.candidates}`; machine at start: {before}.", "",
             "| step | over | wall per item | CPU per item |", "|---|---|---|---|", row, *engine_cost(kept[:20]),
             "", f"Load at the end: {machine()}.", ""]
    if args.engine_cache:
        lines += ["The screen against the faithful values on the paper's 24 (`--engine-cache "
                  + " ".join(args.engine_cache) + "`):", "", *paper_check(args.engine_cache), ""]
    if args.run:
        info = json.loads((Path(args.run) / "design.json").read_text())
        t = info["timings_s"]
        lines += [f"Design run `{args.run}`: config {info['config']}; " + ", ".join(f"{k} {v:.0f} s" for k, v in t.items())
                  + (" (CPU: all processes of the command, the pool's workers included)" if "cpu" in t else "")
                  + f"; {info['passed_screen']} of {info['screened']} candidates passed the screen.", ""]
    text = "\n".join(lines)
    print(text)
    if args.write:
        write_section(ROOT / "docs" / "benchmarks.md", "Stimulus design", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

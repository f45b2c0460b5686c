"""The power table of a designed set beside the paper's 24: SIMULATED studies
through the project's own comparison (analysis.power), the same worlds, the
same number of participants, the same noise, the same seed, on the faithful
effort and risk of each set (the design run's cached stages) and the heuristic
predictors of analysis.heuristics.

Everything here is SIMULATED (analysis.power): no human data.
"""
from __future__ import annotations

import pandas as pd

#: The worlds of the design's power table (issue 34's goals: full with b2/b1 = 2 at
#: sigma 0.10 d; and the issue-32 worlds).
WORLDS: tuple[str, ...] = ("effort-only", "full:b2b1=2,sigma=0.1", "full:b2b1=3,sigma=0.15", "effort+height",
                           "effort+stacked")
#: The verdicts the design cares about: (procedure prefix, verdict) pairs kept in the short table.
PARTICIPANTS = 60
NOISE = 1.0
#: The tests run on both sets: a designed set need not have pairs, so the
#: within-pair permutation (pairs only) is left out of both.
TESTS = ("freedman-lane", "sign-flip")


def available() -> bool:
    try:
        import analysis.power  # noqa: F401
        from analysis.power import power, trial_table  # noqa: F401
    except ImportError:
        return False
    return True


def set_table(trials, effort: pd.DataFrame, risk: pd.DataFrame, ids: dict[str, str] | None, samples: int, seed: int):
    """analysis.power's TrialTable of `trials` (loaded Trials, already named as in
    the output) from the design's faithful tables (`effort`: trial, effort;
    `risk`: trial, sigma, risk), their trial ids renamed by `ids` (candidate id ->
    designed id) when given."""
    from analysis.heuristics import trial_features
    from analysis.power import trial_table

    if ids:
        effort = effort.assign(trial=effort["trial"].map(lambda t: ids.get(t, t)))
        risk = risk.assign(trial=risk["trial"].map(lambda t: ids.get(t, t)))
    feats = trial_features(trials, samples, seed)
    return trial_table(effort[["trial", "effort"]], risk[["trial", "sigma", "risk"]], feats, [t.id for t in trials])


def power_tables(tables: dict, studies: int, seed: int, executor=None, jobs: int = 2, worlds=WORLDS,
                 participants: int = PARTICIPANTS, noise: float = NOISE) -> pd.DataFrame:
    """{set label: TrialTable} -> one power table (analysis.power.power's rows,
    with a column `set`), every set through the same worlds, n, noise and seed."""
    from analysis.power import power

    frames = []
    for label, table in tables.items():
        df = power(table, list(worlds), participants=participants, noise=noise, studies=studies, seed=seed,
                   executor=executor, jobs=jobs, tests=TESTS)
        df = pd.DataFrame(df.to_dict("list"))  # without .attrs (the per-study tables), which pd.concat cannot compare
        frames.append(df.assign(set=label, grouping=table.grouping))
    out = pd.concat(frames, ignore_index=True)
    out.insert(0, "SIMULATED", "SIMULATED studies, not human data")
    return out


def write_power(out, cfg, executor, cache, studies: int, jobs: int = 2, log=print, include_paper: bool = True) -> bool:
    """power.csv of the design folder `out` (its design.csv and finalists/, the
    faithful stages' cache `cache`, hits when the run computed them): the designed
    set and, with `include_paper`, the paper's 24. False (and a log line) when
    analysis.power is not available."""
    from pathlib import Path

    import stimuli
    from lgp.atomic import write_csv_atomic
    from stimuli.design.run import faithful

    out = Path(out)
    if not available():
        log("power table skipped: analysis.power is not available in this checkout")
        return False
    table = pd.read_csv(out / "design.csv", dtype={"designed": str, "candidate_id": str})
    ids = dict(zip(table["candidate_id"], table["designed"]))
    finalists = [stimuli.load_file(out / "finalists" / f"{c}.yaml") for c in table["candidate_id"]]
    effort, risk = faithful(finalists, cfg, executor, cache)
    designed = [stimuli.load_file(out / f"{t}.yaml") for t in table["designed"]]
    tables = {"designed": set_table(designed, effort, risk, ids, cfg.samples, cfg.seed)}
    if include_paper:
        paper = stimuli.load_paper()
        p_effort, p_risk = faithful(paper, cfg, executor, cache)
        tables = {"paper 24": set_table(paper, p_effort, p_risk, None, cfg.samples, cfg.seed), **tables}
    log(f"power: {studies} SIMULATED studies x {len(WORLDS)} worlds x {len(tables)} sets, n = {PARTICIPANTS}, "
        f"noise {NOISE:g} (analysis.power)")
    table = power_tables(tables, studies, cfg.seed, executor, jobs)
    write_csv_atomic(table, out / "power.csv")
    write_csv_atomic(summary(table), out / "power_summary.csv")
    return True


#: The comparisons of the short table: full against each simpler story.
RIVALS = ("effort", "effort+height", "effort+stacked")


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """The short power table: per set, world and rival, the rate at which the
    held-out comparison prefers full over the rival, and the rates at which the
    Freedman-Lane test finds full better (and, where analysis.power tests it, the
    rival better) at alpha .05, each with its Wilson 95% interval."""
    rows = []
    for (label, world), g in table.groupby(["set", "world"], sort=False):
        for rival in RIVALS:
            row = {"SIMULATED": "SIMULATED", "set": label, "world": world, "rival": rival}
            ho = g[(g["procedure"] == f"held-out full vs {rival}") & (g["verdict"] == "full")]
            fl = g[(g["procedure"] == f"freedman-lane full>{rival}") & (g["verdict"].str.startswith("full beats"))]
            flr = g[(g["procedure"] == f"freedman-lane {rival}>full") & (g["verdict"].str.startswith(f"{rival} beats"))]
            for name, part in (("held_out_prefers_full", ho), ("fl_full_better", fl), ("fl_rival_better", flr)):
                if len(part):
                    r = part.iloc[0]
                    row.update({name: r["rate"], f"{name}_low": r["rate_low"], f"{name}_high": r["rate_high"]})
                    row["studies"] = int(r["n_studies"])
            rows.append(row)
    return pd.DataFrame(rows)

"""What a design run writes into its folder (stimuli/design/__main__.py):

| file | content |
|---|---|
| ``D01.yaml`` ... | the designed trials (stimuli/README.md's format; provenance "designed: objective, seed, rank") |
| ``design.csv`` | per designed trial: effort (faithful, M layouts; the screen's proxy; layout 0), risk at every sigma (faithful and screen), height, blocks, stacked, footprint, distance, kind, start |
| ``finalists.csv`` | the same for every finalist (the screen-vs-faithful check's sample) |
| ``discards.csv`` | candidates discarded, by reason |
| ``correlations.csv`` | the predictors' correlation matrix, the paper's 24 and the designed set (tidy: set, a, b, r) |
| ``screen_check.csv`` | Spearman rank correlation of the screen's numbers with the faithful ones, on the finalists and the paper's 24 |
| ``power.csv`` | analysis.power on the paper's 24 and the designed set, same worlds, same n (when analysis.power is available) |
| ``contact_sheet.png`` | the designed trials rendered, A and B (stimuli.render) |
| ``design.json`` | the config, the objective's terms, timings, counts |
| ``finalists/``, ``pictures/``, ``cache/`` | the finalists' trial files, the renders, the faithful stages' cache |
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import spearmanr

from lgp.app.files import write_csv_atomic
from lgp.atomic import write_text_atomic
from stimuli.design.grammar import draw
from stimuli.design.run import Design, write_trial_file

#: Predictors of the correlation matrix (columns of design.csv / the paper's table).
PREDICTORS = ("effort", "height", "blocks", "stacked", "distance", "risk_0.065", "risk_0.1", "risk_0.15", "risk_0.25",
              "risk_prior")
OBJECTIVE_TEXT = "decorrelate risk (0.10, 0.15 d) from height, blocks and effort; spread risk over the prior (stimuli/design/objective.py)"


def trial_ids(k: int) -> list[str]:
    width = max(2, len(str(k)))
    return [f"D{i + 1:0{width}d}" for i in range(k)]


def pair_ids(chosen: pd.DataFrame) -> list[str]:
    """--pairs: ids <pair><E|H> for the chosen rows (in their order). Trials are
    paired by effort (sorted by faithful effort, neighbours paired, ties by
    candidate), and within a pair the one of lower mean risk over the prior is E:
    a pair varies risk at nearly matched effort."""
    order = chosen.sort_values(["effort", "candidate"]).index.tolist()
    ids = {}
    for k in range(0, len(order) - 1, 2):
        a, b = order[k], order[k + 1]
        lo, hi = sorted((a, b), key=lambda i: (chosen.loc[i, "risk_prior"], chosen.loc[i, "candidate"]))
        ids[lo], ids[hi] = f"{k // 2 + 1}E", f"{k // 2 + 1}H"
    return [ids[i] for i in chosen.index]


def output_ids(design: Design) -> list[str]:
    return pair_ids(design.chosen) if design.config.pairs else trial_ids(len(design.chosen))


def write_set(design: Design, out: Path) -> list[Path]:
    """The chosen trials as trial files D01.yaml ... (rank = order by the faithful
    prior risk), or 1E.yaml, 1H.yaml ... with --pairs (`pair_ids`)."""
    cfg = design.config
    paths = []
    for rank, (tid, row) in enumerate(zip(output_ids(design), design.chosen.itertuples()), 1):
        cand = draw(int(row.candidate), cfg.seed, cfg.budget)
        data = dict(cand.data)
        data["id"] = tid
        if cfg.pairs:
            data = {"id": tid, "pair": int(tid[:-1]), "level": tid[-1],
                    **{k: v for k, v in data.items() if k != "id"}}
            data["dimension"] = f"risk at matched effort ({cand.data['dimension']})"
        data["provenance"] = {"designed": [f"designed: objective {OBJECTIVE_TEXT}; seed {cfg.seed}; rank {rank} of "
                                           f"{len(design.chosen)} (by mean risk over the prior); candidate {cand.id} of "
                                           f"{cfg.candidates}"],
                              "generated": cand.data["provenance"]["generated"]}
        paths.append(write_trial_file(data, out / f"{tid}.yaml", f"# Designed trial {tid}: {data['description']}\n"))
    return paths


def design_table(design: Design) -> pd.DataFrame:
    t = design.chosen.copy()
    t.insert(0, "designed", output_ids(design))
    return t.rename(columns={"trial": "candidate_id"})


def correlations(table: pd.DataFrame, label: str) -> pd.DataFrame:
    cols = [c for c in PREDICTORS if c in table.columns]
    m = table[cols].astype(float).corr()
    return pd.DataFrame([{"set": label, "a": a, "b": b, "r": float(m.loc[a, b])} for a in cols for b in cols])


def screen_check(finalists: pd.DataFrame, paper: pd.DataFrame | None, sigmas) -> pd.DataFrame:
    """Spearman rho of screen vs faithful: effort proxy vs effort, and risk per sigma and the prior mean."""
    rows = []
    for label, df in (("finalists", finalists), ("paper 24", paper)):
        if df is None:
            continue
        pairs = [("effort", "effort_proxy", "effort")] + [(f"risk {s:g}", f"screen_risk_{s:g}", f"risk_{s:g}") for s in sigmas
                                                          if f"screen_risk_{s:g}" in df.columns and f"risk_{s:g}" in df.columns]
        pairs.append(("risk over the prior (mean of each grid)", "screen_risk_prior", "risk_prior"))
        for what, a, b in pairs:
            x, y = df[a].astype(float), df[b].astype(float)
            rho = float(spearmanr(x, y).statistic) if x.nunique() > 1 and y.nunique() > 1 else float("nan")
            rows.append({"set": label, "quantity": what, "spearman": rho, "n": len(df)})
    return pd.DataFrame(rows)


def plot_correlations(corr: pd.DataFrame, path: Path) -> Path:
    """Two heat maps: the paper's 24 and the designed set."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    sets = list(dict.fromkeys(corr["set"]))
    fig = Figure(figsize=(6 * len(sets), 5.2))
    FigureCanvasAgg(fig)
    for k, s in enumerate(sets):
        m = corr[corr["set"] == s].pivot(index="a", columns="b", values="r")
        order = [c for c in PREDICTORS if c in m.index]
        m = m.loc[order, order]
        ax = fig.add_subplot(1, len(sets), k + 1)
        im = ax.imshow(m.to_numpy(), vmin=-1, vmax=1, cmap="RdBu_r")
        ax.set_xticks(range(len(order)), order, rotation=60, ha="right", fontsize=8)
        ax.set_yticks(range(len(order)), order, fontsize=8)
        for i in range(len(order)):
            for j in range(len(order)):
                v = m.iloc[i, j]
                ax.text(j, i, "" if np.isnan(v) else f"{v:.2f}", ha="center", va="center", fontsize=6.5)
        ax.set_title(f"{s}: Pearson r between predictors", fontsize=10)
    fig.colorbar(im, ax=fig.axes, shrink=0.8)
    fig.savefig(path, dpi=110)
    return path


def write_json(obj: dict, path: Path) -> Path:
    write_text_atomic(json.dumps(obj, indent=1, default=str) + "\n", path)
    return path


def write_tables(design: Design, out: Path, paper: pd.DataFrame | None) -> dict[str, Path]:
    files = {}
    table = design_table(design)
    files["design"] = write_csv_atomic(table, out / "design.csv") or out / "design.csv"
    write_csv_atomic(design.finalists, out / "finalists.csv")
    write_csv_atomic(pd.DataFrame(sorted(design.reasons.items(), key=lambda kv: -kv[1]), columns=["reason", "count"]),
                     out / "discards.csv")
    corr = correlations(table, "designed")
    if paper is not None:
        corr = pd.concat([correlations(paper, "paper 24"), corr], ignore_index=True)
        write_csv_atomic(paper, out / "paper.csv")
    write_csv_atomic(corr, out / "correlations.csv")
    plot_correlations(corr, out / "correlations.png")
    write_csv_atomic(screen_check(design.finalists, paper, design.config.faithful_sigmas), out / "screen_check.csv")
    return files

"""Pairs over sigma: the paper's risk contrasts over the whole sigma grid
of a run, with their Monte Carlo error, and the required precision per trial.

At the paper's grid (0.05..0.10 d) most faithful risks are 0; past it (about
0.15 d) the paper's risk contrasts appear. This section makes that visible:

* ``pairs_over_sigma.csv``: per (pair, sigma) the risk of E and H with 95% Wilson
  intervals, whether H is riskier beyond Monte Carlo noise (``holds``: H's
  interval lies wholly above E's) and the ratios b2/b1 for which Eq. 1 orders
  the pair E < H (analysis.pairs.ratio_range);
* ``figures/risk_over_sigma.png``: the 24 risk curves, a panel per pair (E and H
  with their intervals), the paper's grid shaded;
* ``risk_precision.csv``: sigma* per trial (models/risk/precision.py);
* a report section and a results-page section.
"""
from __future__ import annotations

import html
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.pairs import ratio_range
from lgp.app.report import ratio_text
from lgp.paper import PAIRS, PAPER_SIGMA, RISK_PAIRS, SIGMA_GRID

COLUMNS = ["pair", "sigma", "risk_E", "risk_E_low", "risk_E_high", "risk_H", "risk_H_low", "risk_H_high", "holds",
           "paper_risk_pair", "effort_E", "effort_H", "tied", "full_E_lt_H_for_b2_over_b1"]
EASY, HARD = "tab:red", "tab:blue"
#: b2/b1 values swept for "how many pairs does one ratio order" (0 = effort weighted by 1 - R only).
_KAPPAS = np.concatenate([[0.0], np.geomspace(0.01, 1000, 801)])


def pairs_over_sigma(effort: pd.DataFrame, risk: pd.DataFrame) -> pd.DataFrame:
    """`effort`: trial, effort (mean over layouts); `risk`: the risk table (trial,
    sigma, risk, risk_low, risk_high). One row per (pair, sigma): COLUMNS."""
    from analysis.pairs import pair_order
    from models.risk.core import contrast_holds

    E = effort.set_index("trial")["effort"].astype(float)
    rows = []
    for sigma, g in risk.groupby("sigma", sort=True):
        by = g.set_index("trial")
        for pair in PAIRS:
            e, h = f"{pair}E", f"{pair}H"
            if e not in by.index or h not in by.index or e not in E.index or h not in E.index:
                continue
            re, rh = by.loc[e], by.loc[h]
            rows.append({"pair": pair, "sigma": float(sigma), "risk_E": re["risk"], "risk_E_low": re["risk_low"],
                         "risk_E_high": re["risk_high"], "risk_H": rh["risk"], "risk_H_low": rh["risk_low"],
                         "risk_H_high": rh["risk_high"], "holds": contrast_holds(re, rh),
                         "paper_risk_pair": pair in RISK_PAIRS, "effort_E": E[e], "effort_H": E[h],
                         "tied": pair_order(E[e], E[h]) == "tie" and pair_order(re["risk"], rh["risk"]) == "tie"})
            rows[-1]["full_E_lt_H_for_b2_over_b1"] = ratio_text(ratio_range(E[e], re["risk"], E[h], rh["risk"], tie=rows[-1]["tied"]))
    return pd.DataFrame(rows, columns=COLUMNS)


@dataclass(frozen=True)
class OverSigma:
    """"Pairs over sigma": the table (pairs_over_sigma), per sigma the most pairs one
    ratio orders (ordered_by_one_ratio) and per pair where its contrast first holds
    (first_holding)."""

    table: pd.DataFrame
    best: pd.DataFrame
    first: pd.DataFrame

    @classmethod
    def of(cls, effort: pd.DataFrame, risk: pd.DataFrame) -> "OverSigma":
        table = pairs_over_sigma(effort, risk)
        return cls(table, ordered_by_one_ratio(table).set_index("sigma"), first_holding(table))


def ordered_by_one_ratio(table: pd.DataFrame) -> pd.DataFrame:
    """Per sigma: the most pairs one ratio b2/b1 >= 0 makes Eq. 1 order E < H, and
    the range of ratios (of a fine sweep) that do so: sigma, best, of, k_min, k_max.
    A pair tied in effort and in risk (the tie rule) is ordered by no ratio."""
    rows = []
    for sigma, g in table.groupby("sigma", sort=True):
        Ee, Re, Eh, Rh = (g[c].to_numpy(float) for c in ("effort_E", "risk_E", "effort_H", "risk_H"))
        a = Eh * (1 - Rh) - Ee * (1 - Re)
        b = Eh * Rh - Ee * Re
        untied = ~g["tied"].to_numpy(bool)
        counts = (((a[None, :] + _KAPPAS[:, None] * b[None, :]) > 0) & untied[None, :]).sum(axis=1)
        best = counts.max()
        ks = _KAPPAS[counts == best]
        rows.append({"sigma": sigma, "best": int(best), "of": len(g), "k_min": float(ks.min()), "k_max": float(ks.max())})
    return pd.DataFrame(rows)


def first_holding(table: pd.DataFrame) -> pd.DataFrame:
    """Per pair: the smallest sigma of the run at which H > E holds beyond Monte
    Carlo noise, and whether it holds at every larger sigma of the run."""
    rows = []
    for pair, g in table.groupby("pair", sort=True):
        g = g.sort_values("sigma")
        held = g["holds"].to_numpy()
        first = g["sigma"].to_numpy()[held.argmax()] if held.any() else np.nan
        rows.append({"pair": pair, "paper_risk_pair": pair in RISK_PAIRS, "first_sigma_holds": first,
                     "holds_above": bool(held.any() and held[held.argmax():].all())})
    return pd.DataFrame(rows)


def plot_risk_over_sigma(table: pd.DataFrame, path: Path, dimensions: dict | None = None) -> Path:
    """The 24 risk curves: a panel per pair (E red, H blue, 95% Wilson bands), the
    paper's grid shaded, the paper's sigma dashed; the paper's risk pairs titled in bold."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    pairs = sorted(table["pair"].unique())
    cols = 6
    rows_n = -(-len(pairs) // cols)
    fig = Figure(figsize=(2.45 * cols, 2.25 * rows_n + 0.6), dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows_n, cols, sharex=True, sharey=True, squeeze=False)
    lo, hi = min(SIGMA_GRID), max(SIGMA_GRID)
    for ax in axes.flat[len(pairs):]:
        ax.set_visible(False)
    for ax, pair in zip(axes.flat, pairs):
        g = table[table["pair"] == pair].sort_values("sigma")
        s = g["sigma"].to_numpy()
        ax.axvspan(lo, hi, color="0.88", zorder=0, lw=0)
        ax.axvline(PAPER_SIGMA, color="0.5", ls="--", lw=0.8, zorder=1)
        for level, colour, dx in (("E", EASY, -0.0008), ("H", HARD, 0.0008)):
            r, low, high = (g[f"risk_{level}{k}"].to_numpy() for k in ("", "_low", "_high"))
            if len(s) == 1:  # one sigma: a point and its interval (a line of one point draws nothing), E left of H
                ax.errorbar(s + dx, r, yerr=[r - low, high - r], fmt="o", color=colour, ms=4, capsize=2, lw=1.2,
                            label=f"{pair}{level}")
                continue
            ax.fill_between(s, low, high, color=colour, alpha=0.18, lw=0)
            ax.plot(s, r, color=colour, lw=1.6, label=f"{pair}{level}")
        held = g[g["holds"]]
        if len(held):
            ax.plot(held["sigma"], np.full(len(held), 1.04), "|", color="k", ms=4, clip_on=False)
        name = (dimensions or {}).get(pair, "")
        ax.set_title(f"pair {pair}" + (f": {name}" if name else ""), fontsize=8.5,
                     fontweight="bold" if pair in RISK_PAIRS else "normal")
        ax.set_ylim(0, 1.06)
        lo_s, hi_s = float(s.min()), float(s.max())
        pad = 0.005 if hi_s == lo_s else 0.0  # one sigma: a point in a narrow window, not a singular axis
        ax.set_xlim(lo_s - pad, hi_s + pad)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.25, lw=0.5)
    for ax in axes[-1]:
        ax.set_xlabel("sigma (units of d)", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("risk", fontsize=8)
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Line2D([], [], color=EASY, lw=1.6, label="E (easy)"), Line2D([], [], color=HARD, lw=1.6, label="H (hard)"),
               Patch(color="0.88", label=f"the paper's grid {lo:g}-{hi:g} d"),
               Line2D([], [], color="0.5", ls="--", lw=0.8, label=f"the paper's sigma {PAPER_SIGMA:g} d"),
               Line2D([], [], color="k", marker="|", ls="", label="H > E beyond Monte Carlo noise")]
    fig.legend(handles=handles, loc="upper center", ncol=5, fontsize=8, frameon=False)
    fig.suptitle("")
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name("." + path.name + ".tmp.png")
    fig.savefig(tmp)
    os.replace(tmp, path)
    return path


def _krange(b) -> str:
    """'>= 1.07' (every ratio of the sweep from there up), '0.5-3.2', or 'none'."""
    if b["best"] == 0:
        return "none"
    if b["k_max"] >= _KAPPAS[-1]:
        return "any" if b["k_min"] <= 0 else f">= {b['k_min']:.3g}"
    return f"{b['k_min']:.3g}-{b['k_max']:.3g}"


def _cell(r) -> str:
    return f"{r['risk_E']:.2f}/{r['risk_H']:.2f}" + ("*" if r["holds"] else "")


def _sigma_rows(table: pd.DataFrame, sigmas=None):
    for sigma, g in table.groupby("sigma", sort=True):
        if sigmas is None or np.isclose(sigmas, sigma).any():
            yield sigma, g.set_index("pair")


def report_lines(over: OverSigma, precision: pd.DataFrame | None, figure: str | None = None) -> list[str]:
    """The report sections "Pairs over sigma" and "Required precision" (markdown lines)."""
    table, best = over.table, over.best
    pairs = sorted(table["pair"].unique())
    lines = ["## Pairs over sigma", "",
             "Risk E / H of every pair at every sigma of the run (fractions of the runs that fall); `*`: H is riskier "
             "beyond Monte Carlo noise (H's 95% Wilson interval lies wholly above E's). The paper's risk pairs are "
             f"{', '.join(map(str, RISK_PAIRS))}; its grid is {min(SIGMA_GRID):g}-{max(SIGMA_GRID):g} d. "
             "Last columns: the most pairs one ratio b2/b1 makes Eq. 1 order E < H, and the ratios that do "
             "(intervals and b2/b1 ranges per pair in pairs_over_sigma.csv).", ""]
    if figure:
        lines += [f"![risk over sigma]({figure})", ""]
    lines += ["| sigma | " + " | ".join(f"{p}{' (risk pair)' if p in RISK_PAIRS else ''}" for p in pairs)
              + " | Eq. 1 orders | for b2/b1 |",
              "|---|" + "---|" * (len(pairs) + 2)]
    for sigma, g in _sigma_rows(table):
        b = best.loc[sigma]
        krange = _krange(b)
        lines.append(f"| {sigma:g} | " + " | ".join(_cell(g.loc[p]) if p in g.index else "" for p in pairs)
                     + f" | {int(b['best'])} of {int(b['of'])} | {krange} |")
    first = over.first
    lines += ["", "Where each contrast first holds beyond Monte Carlo noise (and whether it holds at every larger sigma):", "",
              "| pair | paper's risk pair | first sigma H > E holds | holds at every larger sigma |", "|---|---|---|---|"]
    for _, r in first.iterrows():
        at = "never on this grid" if np.isnan(r["first_sigma_holds"]) else f"{r['first_sigma_holds']:g} d"
        lines.append(f"| {r['pair']} | {'yes' if r['paper_risk_pair'] else ''} | {at} | {'yes' if r['holds_above'] else 'no'} |")
    return lines + [""] + precision_lines(precision)


def precision_lines(precision: pd.DataFrame | None) -> list[str]:
    """The report section "Required precision" (markdown lines; none without a table)."""
    from models.risk.precision import precision_text

    lines = []
    if precision is not None and len(precision):
        levels = list(dict.fromkeys(precision["level"]))
        lines += ["## Required precision", "",
                  "sigma* per trial: the noise level at which its risk first reaches the level, interpolated on the "
                  "run's grid, with a 95% bootstrap interval over runs; `> max` where the grid never reaches it "
                  "(risk_precision.csv, models/risk/precision.py).", "",
                  "| trial | " + " | ".join(f"sigma* (risk {lv:g})" for lv in levels) + " |",
                  "|---|" + "---|" * len(levels)]
        for trial, g in precision.groupby("trial", sort=False):
            by = g.set_index("level")
            lines.append(f"| {trial} | " + " | ".join(precision_text(by.loc[lv]) for lv in levels) + " |")
    return lines + [""]


def page_section(over: OverSigma, figure: Path | None, out: Path) -> str:
    """The results-page section "Pairs over sigma" (HTML)."""
    e = html.escape
    table, best = over.table, over.best
    pairs = sorted(table["pair"].unique())
    head = "".join(f'<th class="{"riskpair" if p in RISK_PAIRS else ""}">{p}</th>' for p in pairs)
    body = []
    for sigma, g in _sigma_rows(table):
        paper = "paper" if min(SIGMA_GRID) - 1e-9 <= sigma <= max(SIGMA_GRID) + 1e-9 else ""
        cells = []
        for p in pairs:
            if p not in g.index:
                cells.append("<td></td>")
                continue
            r = g.loc[p]
            title = (f"{p}E {r['risk_E']:.2f} [{r['risk_E_low']:.2f}, {r['risk_E_high']:.2f}], "
                     f"{p}H {r['risk_H']:.2f} [{r['risk_H_low']:.2f}, {r['risk_H_high']:.2f}]; "
                     f"Eq. 1 orders E < H for b2/b1 {r['full_E_lt_H_for_b2_over_b1']}")
            cells.append(f'<td class="{"holds" if r["holds"] else ""}" title="{e(title)}">{e(_cell(r))}</td>')
        b = best.loc[sigma]
        body.append(f'<tr class="{paper}"><th>{sigma:g}</th>{"".join(cells)}<td>{int(b["best"])} of {int(b["of"])}</td>'
                    f'<td>{e(_krange(b))}</td></tr>')
    img = ""
    if figure is not None:
        rel = os.path.relpath(figure, out)
        img = (f'<figure class="wide"><a href="{e(rel)}"><img src="{e(rel)}" alt="risk over sigma"></a><figcaption>'
               "The 24 risk curves over the run's sigma grid: a panel per pair, E red, H blue, 95% Wilson bands; "
               "grey: the paper's grid; dashed: the paper's sigma; ticks on top: H &gt; E beyond Monte Carlo noise. "
               f'<span class="file">({e(rel)})</span></figcaption></figure>')
    return f"""<section id="over-sigma"><h2>Pairs over sigma</h2>
<p>At the paper's grid ({min(SIGMA_GRID):g}-{max(SIGMA_GRID):g} d, grey rows) most faithful risks are 0; the paper's risk
contrasts (pairs {", ".join(map(str, RISK_PAIRS))}, bold) appear past it. Cells: risk E/H; <b>*</b> and green: H is riskier
beyond Monte Carlo noise (95% Wilson intervals apart; hover for the intervals and the b2/b1 range). Last columns: the
most pairs one ratio b2/b1 makes Eq. 1 order E &lt; H, and the ratios that do. Files: <a href="pairs_over_sigma.csv">pairs_over_sigma.csv</a>,
<a href="risk_precision.csv">risk_precision.csv</a>.</p>
{img}
<table class="oversigma"><thead><tr><th>sigma (d)</th>{head}<th>Eq. 1 orders</th><th>for b2/b1</th></tr></thead>
<tbody>{"".join(body)}</tbody></table></section>"""


__all__ = ["COLUMNS", "OverSigma", "pairs_over_sigma", "ordered_by_one_ratio", "first_holding", "plot_risk_over_sigma",
           "report_lines", "precision_lines", "page_section"]

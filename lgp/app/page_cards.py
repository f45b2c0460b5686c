"""The results page's trial cards: picture, effort, risk curve, plan and replay of one trial."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.charts import histogram_svg, num, risk_svg

from lgp.app.page_parts import plus_minus, table_html
from lgp.app.page_parts import esc as _e


#: The most rows of a per-trial table a trial card shows from.
EXTRA_TABLE_ROWS = 20000


def trial_card(trial, samples: pd.DataFrame, risk: pd.DataFrame, sigma: float, picture: Path | None,
                replay: Path | None, extras: dict[str, pd.DataFrame], out: Path, precision: pd.DataFrame | None = None,
                size: tuple[int, int] | None = None) -> str:
    e = samples["effort"].to_numpy(dtype=float)
    sd = float(np.std(e, ddof=1)) if len(e) > 1 else 0.0
    curve = risk.sort_values("sigma")
    at = curve.loc[np.isclose(curve["sigma"], sigma), "risk"]
    if not trial.initial.is_random:
        effort_text = f"{num(e.mean())} J s"
        effort_note = "fixed layout: A has no random blocks, so it is planned once"
    else:
        effort_text = plus_minus(e.mean(), sd, "J s", len(e))
        effort_note = f"mean &plusmn; sd over {len(e)} layouts"
    if "n_actions" not in samples:
        plan_len = "length not recorded"
    else:
        n_actions = samples.sort_values("sample")["n_actions"].to_numpy()
        plan_len = (f"{int(n_actions[0])} actions" if len(set(n_actions)) == 1
                    else f"{int(n_actions.min())} to {int(n_actions.max())} actions (sample 0: {int(n_actions[0])})")
    pic = ""
    if picture is not None:
        wh = f' width="{size[0]}" height="{size[1]}"' if size else ""
        rel = _e(os.path.relpath(picture, out))
        pic = (f'<a class="pic" href="{rel}" title="{_e(trial.id)}: the picture at full size">'
               f'<img src="{rel}" alt="{_e(trial.id)}: Start (A) and Finish (B)"{wh}></a>')
    has_band = {"risk_low", "risk_high"} <= set(curve.columns)
    band = (curve["risk_low"], curve["risk_high"]) if has_band else ()
    band_note = "; shaded: 95% Wilson interval" if has_band else ""
    link = (f'<a class="replay" href="{_e(os.path.relpath(replay, out))}">3-D replay of sample 0 &#9654;</a>'
            if replay is not None else '<span class="replay none">no replay (--no-replays)</span>')
    more = ""
    if precision is not None and len(precision):
        from models.risk.precision import precision_text

        more += ('<p class="precision"><b>required precision</b> ' + " &middot; ".join(
            f"risk {r['level']:g} at sigma* {_e(precision_text(r))}" for _, r in precision.iterrows()) + "<br>"
            "<small>sigma*: the least noise (sd of each block's displacement, in block widths d) at which B falls in "
            "that fraction of the noisy runs, read off the risk curve, with a 95% bootstrap interval; "
            "&gt; the grid's top: it never did on this run's grid; a smaller sigma* means more precision is needed.</small></p>")
    for title, df in extras.items():
        rows = df[df["trial"] == trial.id]
        if len(rows):
            shown = f"{len(rows)} rows" if len(rows) <= 40 else f"first 40 of {len(rows)} rows, all in {title}.csv"
            more += f'<details><summary>{_e(title.replace("_", " "))} ({_e(shown)})</summary>{table_html(rows.drop(columns=["trial"]), max_rows=40)}</details>'
    return f"""
<article class="card" id="trial-{_e(trial.id)}">
<h3><a href="#trial-{_e(trial.id)}">{_e(trial.id)}</a> <span class="dim">{_e(trial.dimension)}</span></h3>
<p class="desc">{_e(trial.description)}</p>
{pic}
<div class="stats">
<div><b>effort</b> {effort_text}<br><small>{effort_note}</small><br>{histogram_svg(e)}</div>
<div><b>risk</b> {risk_at(curve, sigma)} at sigma {num(sigma)} d<br><small>over sigma, 0 to 1{band_note} (dashed: {num(sigma)} d)</small><br>{risk_svg(curve["sigma"], curve["risk"], sigma, *band)}</div>
</div>
<p><b>plan</b> {plan_len} &middot; {link}</p>
{more}
</article>"""


def risk_at(curve: pd.DataFrame, sigma: float) -> str:
    """'0.17 [0.11, 0.26]': the risk at `sigma` with its 95% Wilson interval when the table has one."""
    at = curve[np.isclose(curve["sigma"], sigma)]
    if not len(at):
        return "n/a"
    r = at.iloc[0]
    if "risk_low" in at:
        return f"{float(r['risk']):.2f} <small>[{float(r['risk_low']):.2f}, {float(r['risk_high']):.2f}]</small>"
    return f"{float(r['risk']):.2f}"

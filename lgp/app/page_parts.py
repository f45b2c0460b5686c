"""The results page's small parts: escaping, numbers in words, sortable tables."""
from __future__ import annotations

import html

import numpy as np
import pandas as pd

from lgp.app.charts import num

#: A spread of effort over layouts below this fraction of the mean is round-off of
#: one and the same plan (a fixed layout of A: 10E's 4.2e-17 on 0.1159 J s), not variation.
PLAN_NOISE = 1e-9


def esc(x) -> str:
    return html.escape(str(x))


def fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return num(v)
    if v is None or (isinstance(v, str) and v.strip().lower() == "nan"):
        return "n/a"
    return str(v)


def plus_minus(mean: float, sd: float, unit: str, n: int) -> str:
    """"0.1159 &plusmn; 0.0021 J s", the sd rounded to 2 digits and the mean to the
    sd's last digit; a spread below the plan noise (all layouts give the same plan up
    to round-off, e.g. 4.2e-17) reads "fixed layout" or "same for every layout"."""
    if n <= 1 or not np.isfinite(sd) or sd <= PLAN_NOISE * max(abs(mean), 1e-12):
        return f"{num(mean)} {unit} <small>(same for every layout)</small>" if n > 1 else f"{num(mean)} {unit}"
    decimals = max(0, 1 - int(np.floor(np.log10(sd))))
    return f"{num(round(mean, decimals))} &plusmn; {num(float(f'{sd:.2g}'))} {unit}"


def p_value(p, n_resamples: int | None) -> str:
    """A bootstrap p value: "< 1/200" when no resample of 200 crossed, else at most 2 digits."""
    try:
        p = float(p)
    except (TypeError, ValueError):
        return "n/a"
    if not np.isfinite(p):
        return "n/a"
    if p == 0 and n_resamples:
        return f"< 1/{int(n_resamples)}"
    return num(p, 2)


def table_html(df: pd.DataFrame, cls: str = "sortable", row_attrs=None, max_rows: int | None = None) -> str:
    """A DataFrame as an HTML table whose header cells sort it (see page.js)."""
    if max_rows is not None and len(df) > max_rows:
        df = df.head(max_rows)
    head = "".join(f"<th>{esc(c)}</th>" for c in df.columns)
    rows = []
    for i, (_, row) in enumerate(df.iterrows()):
        attrs = row_attrs(i, row) if row_attrs else ""
        cells = "".join(f'<td data-v="{esc(v)}">{esc(fmt(v))}</td>' for v in row)
        rows.append(f"<tr{attrs}>{cells}</tr>")
    return f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'


# ----------------------------------------------------------------------------- sections

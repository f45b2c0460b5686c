"""The renderer of --sigma-from (lgp/app/sigma_from.py): the report section, and the
results page's section with the linked sigma beside the run's and the fitted one."""
from __future__ import annotations

import html

from lgp.app.charts import num
from lgp.app.result import Rendered
from lgp.app.sigma_from import SigmaBeside, report_lines


def page_html(data: SigmaBeside) -> str:
    """The page's section: the three sigmas side by side, and the pair table at the linked one."""
    from lgp.app.page_parts import table_html
    from lgp.app.report import pairs_csv_table

    link, e = data.link, html.escape
    lo, hi = link.interval
    rows = [("another lab's data (--sigma-from)", f"{num(link.sigma)} d",
             f"95% interval over participants [{num(lo)}, {num(hi)}] d, held-out r {link.held_out_r:.2f}; "
             f"Mental Jenga experiment {link.experiment}, {link.source}"),
            ("this run's pair table", f"{num(data.run_sigma)} d", "the paper's sigma, or the grid's middle")]
    if data.fitted is not None:
        rows.append(("fitted to the difficulty ratings", f"{num(data.fitted)} d",
                     f"least RMSE of Eq. 1 on dataset {data.fitted_to} (the analysis's sigma choice)"))
    body = "".join(f"<tr><th>{e(a)}</th><td>{e(b)}</td><td>{e(c)}</td></tr>" for a, b, c in rows)
    pairs = ("<p>No pair table at this sigma: it is zero (no noise, so no risk).</p>" if data.pairs is None else
             f"<h3>Pairs at sigma = {num(link.sigma)} d</h3>{table_html(pairs_csv_table(data.pairs))}")
    return (f'<section id="sigma-from"><h2>Sigma from another lab\'s data</h2>'
            f'<table class="plain"><thead><tr><th>sigma</th><th>value</th><th>from</th></tr></thead><tbody>{body}</tbody></table>'
            f"<p>The paper's grid is 0.05-0.10 d (0.065 d {'inside' if lo <= 0.065 <= hi else 'outside'} the interval); "
            f"docs/mental-jenga.md.</p>{pairs}</section>")


def render(data: SigmaBeside, view) -> Rendered:
    from lgp.app.report import markdown_table, pairs_csv_table

    table = None if data.pairs is None else markdown_table(pairs_csv_table(data.pairs))
    return Rendered(report="\n".join(report_lines(data.link, data.run_sigma, data.fitted, table)), page=page_html(data))

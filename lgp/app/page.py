"""The results page: ``<out>/index.html``, one self-contained page of a reproduce run.

Written by every ``python -m lgp.reproduce`` run. It needs no network: the style
and the few lines of JavaScript (sortable tables) are inline, the small charts
(effort histogram, risk curve) are inline SVG, and the pictures are relative files
beside it (``page/7H.png``, ``figures/*.png``, ``replays/7H.html``), so the whole
``results/`` folder can be copied to a laptop and opened with a double click.

Sections: the run (command line, parameters, library versions, engine, wall time
per stage, cache hits); the 12 easy/hard pairs with the paper's claim beside ours;
every figure of the run with a caption; one card per trial (``id="trial-7H"``);
and, with human data, the fits, sigma profile, bootstrap and participants.
"""
from __future__ import annotations

from collections import Counter
import os
import platform
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.files import write_text_atomic
from lgp.app.report import ratio_text, sigma_edge_warnings
from lgp.app.config import QUICK
from lgp.app.charts import num
from lgp.cli import duration_text
from lgp.app.page_cards import EXTRA_TABLE_ROWS, trial_card
from lgp.app.page_human import comparison_section, human_section, participant_table  # noqa: F401
from lgp.app.page_parts import PLAN_NOISE, fmt, p_value, plus_minus, table_html  # noqa: F401
from lgp.app.page_parts import esc as _e
from lgp.errors import InputError

CAPTIONS = {
    "effort_risk_pairs": "Physical effort (J s, mean over layouts) and physical risk (fraction of noisy runs "
                         "that fall) of every trial, easy and hard of each pair joined, pairs named by what they vary. "
                         "Red: E not lower than H, though the paper's participants found H harder; blue hatched: "
                         "pair 11, where they saw no difference (a tie is expected).",
    "fig3_trial_means": "Analogue of the paper's Figure 3, from the data given: mean z-scored judgments per trial (large points, 95% bootstrap "
                        "intervals) and the fitted full model (small points), per dataset.",
    "fig4_model_correlations": "Analogue of the paper's Figure 4, from the data given: correlation of the full model, effort alone and risk alone "
                               "with each dataset, 95% intervals from the bootstrap over participants.",
    "sigma_profile": "RMSE of the fitted full model (Eq. 1) over the noise level sigma, per dataset; "
                     "the chosen sigma marked.",
    "fig4_model_comparison": "Figure 4 in sample and out of sample: correlation of each model with each dataset when "
                             "fit and scored on all 24 trials (pale; Eq. 1 cannot lose to effort-only there) and of its "
                             "held-out predictions (leave-one-pair-out, full colour; leave-one-trial-out, hatched), "
                             "sigma chosen inside each fold; 95% bootstrap intervals.",
    "recovery": "Model recovery on SIMULATED studies from our effort and risk tables: how often the comparison names "
                "the true model, against participants per study (left) and how often Eq. 1 beats effort-only out of "
                "sample against the true sigma (right).",
}


def _asset(name: str) -> str:
    """The page's style (page.css) or script (page.js), inlined so the page needs no other file."""
    return (Path(__file__).parent / name).read_text()


#: What a cache entry of each kind is, in words (the page's run section).
CACHE_WORDS = {"effort": "effort tables (one per trial)", "risk": "risk curves (one per trial)",
               "riskruns": "risk tables (the noisy runs of one trial)", "buildrisk": "risks through the build (one per trial)",
               "sensitivity": "sensitivity tables", "stable": "checks that B stands",
               "picture": "trial pictures (kept in the render cache shared by every run)",
               "replay": "3-D replays"}


def cache_words(counts: dict) -> str:
    """{(kind, outcome): n} as "reused from the cache: 24 effort tables ...; computed: ..."."""
    parts = []
    for outcome, word in (("hit", "reused from the cache"), ("miss", "computed")):
        items = [f"{n} {CACHE_WORDS.get(kind, kind.replace('_', ' '))}" for (kind, o), n in sorted(counts.items()) if o == outcome and n]
        if items:
            parts.append(f"{word}: {', '.join(items)}")
    return "; ".join(parts) or "nothing looked up"


def _run_section(run: dict) -> str:
    key = run.get("key", {})
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in key.items())
    chips = " ".join(f"<code>{_e(k)}={_e(v)}</code>" for k, v in run.get("parameters", {}).items())
    versions = pd.DataFrame(list(run.get("libraries", {}).items()), columns=["library", "version"])
    stages = pd.DataFrame([(k, num(v, 3)) for k, v in run.get("stages", {}).items()], columns=["stage", "wall time (s)"])
    settings = pd.DataFrame(list(run.get("engine_settings", {}).items()), columns=["setting", "value"])
    cache = run.get("cache", {})
    total = sum(run.get("stages", {}).values())
    compute = run.get("compute_s")
    times = f"this run took {duration_text(total)} of wall time"
    if compute is not None:
        times += (f"; computing its effort and risk results took {duration_text(compute)} (the time each part took "
                  "when it was computed, cached parts included)")
    return f"""
<section id="run"><h2>The run</h2>
<p class="cmd"><code>{_e(run.get("command", ""))}</code></p>
<table class="plain key"><caption>The settings that define these results</caption>{rows}</table>
<p>Finished {_e(run.get("finished", ""))}: {_e(times)}, on {_e(run.get("machine", platform.node()))}
({_e(run.get("load", ""))}). {cache.get("hits", 0)} results reused from the cache, {cache.get("misses", 0)} computed
({_e(cache.get("words", ""))}).</p>
<details><summary>Every parameter, wall time per stage, the risk engine's settings, library versions</summary>
<p class="params">{chips}</p>
<p>Cache folder <code>{_e(cache.get("root", ""))}</code>.</p>
<div class="grid4">
<div><h3>Wall time per stage</h3>{table_html(stages)}</div>
<div><h3>Risk engine: {_e(run.get("engine", ""))}</h3>{table_html(settings, "plain")}</div>
<div><h3>Libraries</h3>{table_html(versions, "plain")}</div>
</div></details></section>"""


def _quick_banner(run: dict) -> str:
    if not run.get("quick"):
        return ""
    key = run.get("key", {})
    return (f'<p class="banner" id="quick">Low-precision preview (<code>--quick</code>: M = {_e(key.get("M, layouts of A per trial", QUICK["samples"]))} '
            f'layouts, N = {_e(key.get("N, noisy runs per trial and sigma", QUICK["n_sims"]))} runs, sigmas {_e(key.get("sigmas (units of d)", ""))}): '
            "numbers are noisier than the paper's; run without <code>--quick</code> for the full reproduction.</p>")


def carry_doc(name: str, text: str | None, out: Path) -> Path | None:
    """docs/<name> (its `text`, read by the run) written as ``<out>/page/<stem>.html``
    (escaped, in a readable page), so the output folder holds what the page links;
    None when the run had no such doc (an installed copy)."""
    if text is None:
        return None
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_e(name)}</title><style>body{{font:15px/1.5 system-ui,sans-serif;margin:0 auto;max-width:50em;padding:10px 16px;color:#1d1d1f}}
pre{{white-space:pre-wrap;word-wrap:break-word;font:14px/1.5 ui-monospace,monospace}}</style></head>
<body><p><a href="../index.html">&larr; results page</a> &middot; docs/{_e(name)} of the checkout that wrote this folder,
as it read then (Markdown)</p><pre>{_e(text)}</pre></body></html>
"""
    return write_text_atomic(page, Path(out) / "page" / f"{Path(name).stem}.html")


def _docs_link(name: str, docs: dict, out: Path, text: str) -> str:
    """A link to docs/<name>, carried into the output folder (`carry_doc`) so that
    the link holds when the folder is copied; text only when the docs are not here."""
    carried = carry_doc(name, docs.get(name), out)
    if carried is None:
        return f"{_e(text)} (docs/{_e(name)} of the source)"
    return f'<a href="{_e(os.path.relpath(carried, out))}">{_e(text)}</a>'


def risk_explanation(risk: pd.DataFrame, sigma: float, trials, out: Path, docs: dict | None = None) -> str:
    """One sentence on what a reader sees in the risk numbers: how many trials never
    fall at the pairs' sigma, and which trials have the very same curve (equal
    structures perturbed with the same random numbers), with the link to docs/risk.md."""
    at = risk[np.isclose(risk["sigma"].astype(float), sigma)]
    zero = sorted(at.loc[at["risk"] == 0, "trial"].astype(str), key=[t.id for t in trials].index)
    curves: dict[tuple, list[str]] = {}
    for tid, g in risk.groupby("trial", sort=False):
        c = tuple(np.round(g.sort_values("sigma")["risk"].to_numpy(dtype=float), 12))
        if any(c):
            curves.setdefault(c, []).append(str(tid))
    same = [ids for ids in curves.values() if len(ids) > 1]
    text = (f"At sigma = {num(sigma)} d, B of {len(zero)} of the {at['trial'].nunique()} trials stood in every noisy run "
            f"(risk 0): noise of sd {num(sigma)} d per block seldom shifts a block the ~0.5 d past its support's edge that tipping needs. ")
    if same:
        text += ("Trials with the same structure have identical risk curves ("
                 + "; ".join(" = ".join(ids) for ids in same)
                 + ") because every trial is perturbed with the same random numbers (common random numbers: equal "
                   "structures get equal risks, and a difference between trials is not blurred by independent noise). ")
    else:
        text += "Every trial is perturbed with the same random numbers (common random numbers): equal structures get equal curves. "
    return _e(text) + "Why: " + _docs_link("risk.md", docs or {}, out, "docs/risk.md") + "."


def key_settings(args, trials) -> dict:
    """The few settings that define a run's results (the rest are folded on the page)."""
    from lgp.paper import TRIAL_IDS

    ids = [t.id for t in trials]
    shown = "the paper's 24" if sorted(ids) == sorted(TRIAL_IDS) else (", ".join(ids) if len(ids) <= 12 else f"{', '.join(ids[:10])} ...")
    sigmas = getattr(args, "sigmas", ()) or ()
    model = args.risk_model
    design = getattr(args, "approach_height", None)
    return {
        "trials": f"{len(ids)} ({shown})",
        "M, layouts of A per trial": getattr(args, "samples", ""),
        "N, noisy runs per trial and sigma": getattr(args, "n_sims", ""),
        "sigmas (units of d)": ", ".join(num(x) for x in sigmas) if len(sigmas) <= 6 else
                               f"{len(sigmas)} from {num(min(sigmas))} to {num(max(sigmas))}",
        "risk engine": model.engine + (f" ({args.profile} profile)" if args.profile else ""),
        "fall rule": model.fall_text,
        "effort design": (f"approach leg {num(design)} m" if design else "no approach leg (clearance constraint)")
                         + f", {getattr(args, 'slices', '')} slices per phase",
        "seed": getattr(args, "seed", ""),
    }


def pair_verdicts(pairs: pd.DataFrame) -> pd.DataFrame:
    """The pair table with the paper's claim beside ours and whether they differ
    (analysis.pairs.pair_verdicts), in words.

    Ours: whether Eq. 1 (b1 > 0) can order the pair E < H for some b2/b1 >= 0, from
    the ratio range of analysis.pairs.pair_orderings; a pair tied in effort and in
    risk (the tie rule, analysis.pairs.TIE_REL) is a tie.
    """
    from analysis.pairs import pair_verdicts as verdicts, ratio_ranges

    v = verdicts(pairs)
    df = pairs.copy()
    df["paper (full model)"] = ["E < H" if o else "not ordered (humans: no difference)" for o in v["paper_ordered"]]
    df["ours (Eq. 1)"] = ["tie" if r.tie else "E < H for any b2/b1" if r.every else "not ordered" if r.empty
                          else f"E < H for b2/b1 {ratio_text(r)}" for r in ratio_ranges(pairs)]
    df["differs"] = v["differs"].to_numpy()
    return df


def percent(x) -> str:
    """A relative difference as a percentage of at most 4 significant digits; below
    the effort tie rule's 1e-4 it is round-off, written 0 %."""
    from analysis.pairs import TIE_REL

    x = float(x)
    if not np.isfinite(x):
        return "n/a"
    if abs(x) < TIE_REL / 100:
        return "0 %"
    sign = "+" if x > 0 else ""
    if abs(x) < TIE_REL:  # the tie rule's plan noise: one digit says all there is
        return f"{sign}{num(100 * x, 1)} % (tie)"
    return f"{sign}{num(100 * x, 3)} %"


def _pairs_section(pairs: pd.DataFrame | None, analysis: dict | None, figure_sigma=None) -> str:
    from analysis.pairs import TIE_REL

    if pairs is None:
        return '<section id="pairs"><h2>Easy/hard pairs</h2><p>No pair table: no two trials of this run are the easy and hard trial of one pair (a subset of the paper&#x27;s pairs, or a trial set without pairs).</p></section>'
    df = pair_verdicts(pairs)
    sigma = df["sigma"].iloc[0]
    show = df[["pair", "dimension", "effort_E", "effort_H", "effort_rel_diff", "risk_E", "risk_H",
               "paper (full model)", "ours (Eq. 1)", "differs"]].rename(columns={"effort_rel_diff": "(H-E)/E"})
    show["(H-E)/E"] = [percent(x) for x in show["(H-E)/E"]]
    extra = ""
    if analysis is not None and "pairs" in analysis:
        fitted = analysis["pairs"]
        fitted = fitted[fitted["source"] == "full"]
        if len(fitted):
            wide = fitted.pivot_table(index="pair", columns="dataset", values="E_lt_H", aggfunc="first")
            for d in wide.columns:
                show.insert(len(show.columns) - 1, f"fitted full, {d}: E < H", show["pair"].map(wide[d]).map(lambda v: "yes" if v else "no"))

    def attrs(i, row):
        return f' class="pair-row{" differs" if row["differs"] else ""}" id="pair-{int(row["pair"])}"'

    n_diff = int(df["differs"].sum())
    note = ""
    if figure_sigma is not None and not np.isclose(figure_sigma[0], sigma):
        note = (f" (this table's one sigma; the figures of the fits use the fitted sigma = {num(figure_sigma[0])} d, "
                "so their pair orderings can differ from this table's)")
    warn = "".join(f'<p class="warn">Warning: {_e(w)}.</p>' for w in sigma_edge_warnings(analysis))
    return f"""
<section id="pairs"><h2>Easy/hard pairs</h2>
{warn}<p>Effort in J s (mean over layouts), risk at sigma = {num(sigma)} d{note}. The paper's fitted full model ordered 11 of 12 pairs
E &lt; H, pair 11 the exception. Without fitted betas ours says for which ratios b2/b1 (b1 &gt; 0) Eq. 1 would order
the pair E &lt; H; a pair tied in effort and in risk (|H - E| &le; {TIE_REL:g} max(E, H), the tie rule of
every table) is a tie.
<strong>{n_diff} of {len(df)} pairs differ from the paper</strong> (marked <span class="differs-key">&#x2260;</span>).</p>
{table_html(show.assign(differs=show["differs"].map(lambda v: "≠" if v else "")), row_attrs=attrs)}
</section>"""


def _figures_section(figures: list[Path], out: Path, sigma: float | None = None, rule: str | None = None) -> str:
    """Every figure with its caption; a figure of risk names the one sigma it shows
    (`sigma`, chosen by `rule`)."""
    if not figures:
        return ""
    items = []
    for f in figures:
        stem = f.stem.removeprefix("simulated_")
        caption = CAPTIONS.get(stem, stem.replace("_", " "))
        if stem == "effort_risk_pairs" and sigma is not None:
            if rule == "given by caller":
                rule = "the pair table's sigma"
            caption += f" Risk at sigma = {num(sigma)} d" + (f" ({rule})." if rule else ".")
        if f.stem.startswith("simulated_"):
            caption = "SIMULATED participants, not human data. " + caption
        rel = os.path.relpath(f, out)
        items.append(f'<figure><a href="{_e(rel)}"><img src="{_e(rel)}" alt="{_e(stem)}"></a>'
                     f'<figcaption>{_e(caption)} <span class="file">({_e(rel)})</span></figcaption></figure>')
    return f'<section id="figures"><h2>Figures</h2>{"".join(items)}</section>'


def write_page(out, *, run: dict, trials, effort_samples: pd.DataFrame, risk: pd.DataFrame, sigma: float,
               pairs: pd.DataFrame | None = None, analysis: dict | None = None, figures=(),
               pictures: dict | None = None, replays: dict | None = None,
               figure_sigma: tuple[float, str] | None = None, over_sigma_html: str | None = None,
               precision: pd.DataFrame | None = None, extras: dict | None = None, sections_html=(),
               picture_sizes: dict | None = None, recovery: pd.DataFrame | None = None, docs: dict | None = None) -> Path:
    """Write ``<out>/index.html`` (atomically) and return its path.

    `run`: command, parameters, engine, engine_settings, stages (name -> s),
    cache (hits, misses, root), finished, load. `pictures` and `replays` map trial
    ids to files under `out`; `figures` are PNG files under `out`; `extras`: the
    run's per-trial tables by name (shown on the cards); `sections_html`: the
    feature sections' page parts (after the pair tables).
    """
    out = Path(out)
    pictures, replays, sizes = pictures or {}, replays or {}, picture_sizes or {}
    extras = {name: df.head(EXTRA_TABLE_ROWS) for name, df in sorted((extras or {}).items()) if "trial" in df.columns}
    cards = []
    for trial in trials:
        s = effort_samples[effort_samples["trial"] == trial.id]
        r = risk[risk["trial"] == trial.id]
        if not len(s) or not len(r):
            raise InputError(f"results page: trial {trial.id} has no effort or no risk rows")
        prec = None if precision is None else precision[precision["trial"] == trial.id]
        cards.append(trial_card(trial, s, r, sigma, pictures.get(trial.id), replays.get(trial.id), extras, out, prec,
                                 sizes.get(trial.id)))
    nav = " ".join(f'<a href="#trial-{_e(t.id)}">{_e(t.id)}</a>' for t in trials)
    comparison = comparison_section(analysis, recovery)  # "" when there is nothing to compare: no link to it
    title = "Effort and risk: reproduction of Yildirim, Saeed et al. (CogSci 2019)"
    body = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_e(title)}</title><style>{_asset('page.css')}</style></head>
<body>
<header><h1>{_e(title)}</h1>
<nav><a href="#run">run</a> <a href="#pairs">pairs</a>{' <a href="#over-sigma">pairs over sigma</a>' if over_sigma_html else ''}{' <a href="#figures">figures</a>' if figures else ''} <a href="#trials">trials</a> <a href="#human">human data</a>{' <a href="#comparison">model comparison</a>' if comparison else ''}
&middot; files: <a href="report.md">report.md</a> <a href="effort.csv">effort.csv</a> <a href="effort_samples.csv">effort_samples.csv</a> <a href="risk.csv">risk.csv</a>{' <a href="pairs.csv">pairs.csv</a>' if pairs is not None else ''}</nav>
</header>
<main>
{_quick_banner(run)}
{_run_section(run)}
{_pairs_section(pairs, analysis, figure_sigma)}
{over_sigma_html or ""}{"".join(sections_html)}
{_figures_section([Path(f) for f in figures], out, *(figure_sigma or (None, None)))}
<section id="trials"><h2>Trials</h2><p class="trialnav">{nav}</p>
<p>A is the layout of sample 0 (the one the replay plays); effort is over all {effort_samples.groupby("trial").size().max()} layouts.
Histogram: effort per layout. Risk: fraction of noisy runs of B that fall, over the run's sigma grid, every
mini-plot on the same axis from 0 to 1 (a risk of 0.05, one fall in 20, stays near the floor), with the 95% Wilson
interval of each point shaded where the table has it. Click a picture for its full size.</p>
<p class="explain">{risk_explanation(risk, sigma, trials, out, docs)}</p>
<div class="cards">{"".join(cards)}</div></section>
{human_section(analysis)}
{comparison}
</main>
<footer>Written by <code>python -m lgp.reproduce</code>; every file it links is beside this page.</footer>
<script>{_asset('page.js')}</script>
</body></html>
"""
    return write_text_atomic(body, out / "index.html")


def _parameter(v) -> str:
    """A setting of the run as the page's chips show it."""
    if isinstance(v, tuple):
        return ", ".join(f"{x:g}" if isinstance(x, float) else str(x) for x in v)
    return "(default)" if v is None else str(v)


def run_record(result) -> dict:
    """The page's run section of a RunResult: its settings and its RunRecord, in words."""
    from models.risk import DEFAULT_ENGINE

    config, record = result.config, result.record
    counts = Counter()
    for (kind, outcome), n in record.cache_counts.items():
        counts[kind, "hit" if outcome == "hit" else "miss"] += n
    counts.update(record.cache_files)
    files = record.cache_files
    return {
        "command": config.command or f"lgp.reproduce.main(...) from {Path(sys.argv[0]).name}: parameters below",
        "key": key_settings(config, result.trials),
        "quick": bool(config.quick),
        "compute_s": record.compute[0],
        "parameters": {k: _parameter(v) for k, v in config.parameters().items()},
        "engine": config.engine or DEFAULT_ENGINE,
        "engine_settings": record.software["engine"],
        "libraries": record.recorded_libraries,
        "stages": dict(record.stages),
        "cache": {"hits": sum(n for (_, o), n in record.cache_counts.items() if o == "hit")
                          + sum(n for (_, o), n in files.items() if o == "hit"),
                  "misses": sum(n for (_, o), n in record.cache_counts.items() if o != "hit")
                            + sum(n for (_, o), n in files.items() if o == "miss"),
                  "root": record.cache_root, "words": cache_words(counts)},
        "finished": record.finished,
        "machine": record.machine,
        "load": record.load,
    }


def write_index(result, out, *, figures=(), card_tables: dict | None = None, section_pages=(),
                over_figure: Path | None = None) -> Path:
    """The page of a RunResult (lgp.app.result) in `out`: `figures` (PNG files written
    there), the feature sections' card tables and page parts, and the figure of
    "Pairs over sigma"."""
    from lgp.app import over_sigma

    out = Path(out)
    figure_sigma = None
    settings_table = result.analysis.get("settings") if result.analysis is not None else None
    if isinstance(settings_table, pd.DataFrame) and len(settings_table) and "sigma" in settings_table:
        figure_sigma = (float(settings_table["sigma"].iloc[0]), str(settings_table.get("sigma_rule", pd.Series([""])).iloc[0]))
    over_html = over_sigma.page_section(result.over_sigma, over_figure, out) if result.over_sigma is not None else None
    recovery = result.section("recovery")
    return write_page(out, run=run_record(result), trials=result.trials, effort_samples=result.effort_samples,
                      risk=result.risk, sigma=result.sigma, pairs=result.pairs, figure_sigma=figure_sigma,
                      analysis=result.analysis if result.human else None, figures=figures,
                      pictures=result.pictures, replays=result.replays, over_sigma_html=over_html,
                      precision=result.precision, extras=card_tables, sections_html=section_pages,
                      picture_sizes=result.picture_sizes, recovery=None if recovery is None else recovery.data.summary,
                      docs=result.docs)

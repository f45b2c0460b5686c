"""The results page's sections on human data: the fits, sigma profile, bootstrap and participants, and the model comparison."""
from __future__ import annotations


import numpy as np
import pandas as pd

from lgp.app.page_parts import p_value, table_html
from lgp.app.page_parts import esc as _e
from lgp.app.report import sigma_edge_warnings


def human_section(analysis: dict | None) -> str:
    if analysis is None:
        return ('<section id="human"><h2>Human data</h2><p>No human data given (<code>--human-data FILE.csv</code>, '
                'format in docs/human-data.md): the fits of Eq. 1, the sigma profile and the bootstrap need the responses, '
                'which are not public.</p></section>')
    settings = analysis.get("settings")
    simulated = bool(settings["simulated"].iloc[0]) if settings is not None and "simulated" in settings else False
    parts = ['<section id="human"><h2>Human data: fits, sigma profile, bootstrap</h2>']
    if simulated:
        parts.append('<p class="warn">SIMULATED participants, not human data.</p>')
    parts += [f'<p class="warn">Warning: {_e(w)}.</p>' for w in sigma_edge_warnings(analysis)]
    if settings is not None:
        parts.append(table_html(settings.T.reset_index().set_axis(["setting", "value"], axis=1), "plain"))
    for key, title in (("fits", "Fits of Eq. 1 and its lesions (in-sample)"), ("sigma_choice", "Sigma chosen by RMSE"),
                       ("sigma_profile", "RMSE profile over sigma"),
                       ("bootstrap_summary", "Bootstrap over participants (in-sample)"),
                       ("bootstrap_tests", "Direct bootstrap tests (in-sample; full vs effort cannot fail there)"),
                       ("excluded_participants", "Excluded participants")):
        df = analysis.get(key)
        if isinstance(df, pd.DataFrame) and len(df) and "p_value" in df:
            n = df["n_boot"] if "n_boot" in df else pd.Series([None] * len(df), index=df.index)
            df = df.assign(p_value=[p_value(p, k) for p, k in zip(df["p_value"], n)])
        if isinstance(df, pd.DataFrame) and len(df):
            parts.append(f"<h3>{_e(title)}</h3>{table_html(df, max_rows=400)}")
    z = analysis.get("zscored")
    pred = analysis.get("predictions")
    if isinstance(z, pd.DataFrame) and len(z):
        parts.append(f"<h3>Participants</h3>{table_html(participant_table(z, pred), max_rows=2000)}")
    parts.append("</section>")
    return "".join(parts)


def comparison_section(analysis: dict | None, recovery: pd.DataFrame | None = None) -> str:
    """Model comparison: in-sample and out-of-sample side by side, the tests, the
    permutation tests (with human data), and the recovery table of SIMULATED
    studies when recovery/ holds one (--recovery)."""
    from analysis import compare_report as cr

    parts = []
    if analysis is not None and "model_comparison" in analysis:
        parts += [f"<p>{_e(cr.CANNOT_FAIL)}</p>",
                  f"<h3>Scores in sample and out of sample</h3>{table_html(cr.side_by_side(analysis['model_comparison']), 'plain')}"]
        parts += _ceiling_part(analysis.get("noise_ceiling"))
        parts += _decision_part(analysis.get("model_comparison_held_out_permutation"))
        parts += [f"<h3>Eq. 1 against effort-only: direct bootstrap tests (the paper's method, NOT CALIBRATED: "
                  f"shown to compare, not to decide)</h3>"
                  f"{table_html(cr.tests_table(analysis['model_comparison_tests']), 'plain')}",
                  f"<p>{_e(cr.widening_text(analysis['model_comparison']))}</p>"]
        if "permutation_test" in analysis:
            parts.append(f"<h3>Permutation tests of the risk term</h3>"
                         f"{table_html(cr.permutation_table(analysis['permutation_test']), 'plain')}")
    if recovery is not None:
        summary = recovery
        parts.append('<h3>Model recovery on SIMULATED studies (not human data)</h3>'
                     '<p class="warn">SIMULATED participants, not human data: could a study of this design tell the '
                     'models apart on these effort and risk tables?</p>')
        for source in summary["source"].unique():
            parts.append(f"<p>Parameters {_e(source)}:</p>{table_html(cr.recovery_table(summary, source=source), 'plain')}")
    if not parts:
        return ""
    return '<section id="comparison"><h2>Model comparison: in-sample and out of sample</h2>' + "".join(parts) + "</section>"


def _ceiling_part(ceiling) -> list[str]:
    """The noise ceiling beside the model scores (analysis.reliability), labelled."""
    if not isinstance(ceiling, pd.DataFrame) or not len(ceiling):
        return []
    cols = ["dataset", "participants", "reliability", "reliability_low", "reliability_high", "r_ceiling",
            "r_ceiling_low", "r_ceiling_high"]
    return ["<h3>Noise ceiling beside the scores</h3>"
            "<p>Split-half reliability of the trial means, Spearman-Brown corrected, and r_ceiling = "
            "sqrt(reliability): the r a model predicting the true trial means would reach; compare each model's r "
            "above with it (95% intervals centred on the point, participants resampled; analysis.reliability).</p>"
            f"{table_html(ceiling[cols].round(3), 'plain')}"]


def _decision_part(perm) -> list[str]:
    """The calibrated held-out comparison test (analysis.crossval.permuted): the decision."""
    if not isinstance(perm, pd.DataFrame) or not len(perm):
        return []
    shown = perm[["dataset", "model_a", "model_b", "rmse_a", "rmse_b", "observed", "n_perm"]].round(4).assign(
        p_value=[p_value(p, n) for p, n in zip(perm["p_value"], perm["n_perm"])])
    folds = "; ".join(dict.fromkeys(perm["folds"].astype(str)))
    return ["<h3>The decision: held-out comparison test (calibrated)</h3>"
            "<p>p of &quot;model_a predicts held-out trials better than model_b&quot;: the held-out RMSE difference "
            "(observed = rmse_b - rmse_a) on folds by structure against its Freedman-Lane null (residuals of "
            "model_b&#x27;s fit permuted, everything refit, sigma chosen inside every fold; "
            f"analysis.crossval.permuted). Folds: {_e(folds)}.</p>"
            f"{table_html(shown, 'plain', max_rows=400)}"]


def participant_table(zscored: pd.DataFrame, predictions: pd.DataFrame | None) -> pd.DataFrame:
    """Per participant: responses, and the correlation of their z-scores with the fitted full model."""
    value = "z" if "z" in zscored.columns else [c for c in zscored.columns if c not in ("dataset", "participant", "trial")][-1]
    rows = []
    full = None
    if isinstance(predictions, pd.DataFrame) and len(predictions):
        full = predictions[predictions["model"] == "full"].set_index(["dataset", "trial"])["predicted"]
    for (d, p), g in zscored.groupby(["dataset", "participant"], sort=True):
        row = {"dataset": d, "participant": p, "responses": len(g)}
        if "response" in g:
            row["mean response"] = float(g["response"].mean())
        if full is not None:
            m = full.reindex(list(zip([d] * len(g), g["trial"]))).to_numpy()
            ok = np.isfinite(m)
            row["r with full model"] = float(np.corrcoef(g[value].to_numpy()[ok], m[ok])[0, 1]) if ok.sum() > 2 else float("nan")
        rows.append(row)
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- the page

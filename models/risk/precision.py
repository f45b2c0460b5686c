"""Required precision (beyond the paper): per trial, the noise level
sigma* at which its risk first reaches a level (0.5 and 0.1 by default). It
answers "how careful must one be to build this" without choosing a sigma.

sigma* is read off the risk curve over the grid of the run: the first grid
point whose risk is >= the level, interpolated linearly with the point before
it. It is **right-censored** ("> grid max") when no point of the grid reaches
the level and **left-censored** ("<= grid min") when the smallest sigma already
does. Its interval is a bootstrap over runs: the runs (run r sees the same
normals at every sigma, common random numbers) are resampled with replacement,
the curve of each resample is read the same way, and the interval is the 2.5th
and 97.5th percentiles; a resample that never reaches the level counts as
+inf, so an upper bound can be "> grid max" (inf in the CSV).

    from models.risk import risk_table
    from models.risk.precision import required_precision
    runs = risk_table(trials, WIDE_SIGMA_GRID, runs=True)
    required_precision(runs)          # one row per (trial, level): PRECISION_COLUMNS
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from lgp.errors import InputError
from models.risk.model import MODEL_COLUMNS

#: The risk levels of sigma* (fractions of runs that fall).
PRECISION_LEVELS: tuple[float, ...] = (0.5, 0.1)
#: Bootstrap resamples of the runs.
N_BOOT = 1000
PRECISION_COLUMNS = ["trial", "level", "sigma_star", "sigma_low", "sigma_high", "censored", "grid_min", "grid_max",
                     "n_sigmas", "n_sims", "n_boot", *MODEL_COLUMNS]


def check_levels(levels: Sequence[float]) -> tuple[float, ...]:
    """Precision levels checked: each a number in (0, 1); ValueError otherwise."""
    out = []
    for level in levels:
        try:
            value = float(level)
        except (TypeError, ValueError):
            raise InputError(f"a precision level must be a risk in (0, 1), got {level!r}") from None
        if not (0 < value < 1):
            raise InputError(f"a precision level must be a risk in (0, 1), got {level!r}")
        out.append(value)
    if not out:
        raise InputError("need at least one precision level in (0, 1)")
    return tuple(out)


def first_crossing(sigmas: np.ndarray, curves: np.ndarray, level: float) -> np.ndarray:
    """Where each risk curve (rows of `curves`, over increasing `sigmas`) first
    reaches `level`, interpolated linearly: +inf where it never does, sigmas[0]
    where the first point already does."""
    curves = np.atleast_2d(curves)
    hit = curves >= level
    k = hit.argmax(axis=1)
    out = np.full(len(curves), np.inf)
    reached = hit.any(axis=1)
    first = reached & (k == 0)
    out[first] = sigmas[0]
    mid = reached & (k > 0)
    if mid.any():
        rows = np.flatnonzero(mid)
        kk = k[rows]
        s0, s1 = sigmas[kk - 1], sigmas[kk]
        r0, r1 = curves[rows, kk - 1], curves[rows, kk]
        out[rows] = s0 + (level - r0) / (r1 - r0) * (s1 - s0)  # r0 < level <= r1, so r1 > r0
    return out


def required_precision(runs: pd.DataFrame, levels: Sequence[float] = PRECISION_LEVELS, n_boot: int = N_BOOT,
                       seed: int = 0) -> pd.DataFrame:
    """sigma* per trial and level from a per-run risk table (columns trial,
    sigma, run, fell; engine and rules when present): PRECISION_COLUMNS, one row
    per (trial, level) in the table's trial order. Every trial needs the same
    runs at every sigma (a `risk_table(..., runs=True)` table has them)."""
    levels = check_levels(levels)
    if n_boot < 1:
        raise InputError(f"need n_boot >= 1 bootstrap resamples, got {n_boot}")
    rng = np.random.default_rng(seed)
    rows = []
    for trial, g in runs.groupby("trial", sort=False):
        wide = g.pivot_table(index="run", columns="sigma", values="fell", aggfunc="first")
        if wide.isna().any().any():
            raise InputError(f"trial {trial}: required precision needs the same runs at every sigma")
        sigmas = wide.columns.to_numpy(float)
        fell = wide.to_numpy(bool)
        n = len(fell)
        curve = fell.mean(axis=0)
        idx = rng.integers(0, n, size=(n_boot, n))
        boot = np.stack([fell[i].mean(axis=0) for i in idx]) if n_boot else np.empty((0, len(sigmas)))
        rules = {k: (g[k].iloc[0] if k in g else None) for k in MODEL_COLUMNS}
        for level in levels:
            star = first_crossing(sigmas, curve, level)[0]
            if np.isinf(star):
                censored, value = "right", np.nan
            elif star == sigmas[0] and curve[0] >= level:
                censored, value = "left", np.nan
            else:
                censored, value = "none", float(star)
            b = first_crossing(sigmas, boot, level)
            low, high = np.percentile(b, [2.5, 97.5], method="inverted_cdf")  # no interpolation: bounds may be inf
            rows.append({"trial": trial, "level": level, "sigma_star": value, "sigma_low": float(low),
                         "sigma_high": float(high), "censored": censored, "grid_min": float(sigmas[0]),
                         "grid_max": float(sigmas[-1]), "n_sigmas": len(sigmas), "n_sims": n, "n_boot": n_boot, **rules})
    return pd.DataFrame(rows, columns=PRECISION_COLUMNS)


def precision_text(row) -> str:
    """sigma* of one row for reports and trial cards: '0.142 d [0.131, 0.155]',
    '> 0.3 d' (right-censored), '<= 0.05 d' (left-censored)."""
    def bound(x):
        return f"> {row['grid_max']:g}" if np.isinf(x) else f"{x:.3g}"

    if row["censored"] == "right":
        return f"> {row['grid_max']:g} d"
    if row["censored"] == "left":
        return f"<= {row['grid_min']:g} d"
    return f"{row['sigma_star']:.3g} d [{bound(row['sigma_low'])}, {bound(row['sigma_high'])}]"


__all__ = ["PRECISION_LEVELS", "PRECISION_COLUMNS", "N_BOOT", "check_levels", "first_crossing", "required_precision",
           "precision_text"]

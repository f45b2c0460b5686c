"""The results page's small charts as inline SVG (no picture files, no library):
a histogram of effort over layouts and a risk curve over sigma, one of each per
trial card."""
from __future__ import annotations

import numpy as np


#: No number on the page prints more than this many significant digits.
DIGITS = 4


def num(v, digits: int = DIGITS) -> str:
    """A number for a reader: at most `digits` significant digits ("0.1159", "2124",
    "1.5e-05"); nan/None -> "n/a"."""
    if v is None:
        return "n/a"
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not np.isfinite(x):
        return "n/a" if np.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == int(x) and abs(x) < 1e6 and len(str(abs(int(x))).rstrip("0")) <= digits:
        return str(int(x))  # 2124, 20000, 26400: whole numbers as written
    return f"{x:.{digits}g}"


def histogram_svg(values, width: int = 180, height: int = 56, bins: int = 10) -> str:
    """A tiny histogram of `values` as inline SVG (axis: min and max printed below)."""
    v = np.asarray(values, dtype=float)
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < 1e-12 * max(1.0, abs(hi)):
        counts, edges = np.array([len(v)]), np.array([lo, hi])
    else:
        counts, edges = np.histogram(v, bins=bins, range=(lo, hi))
    plot_h = height - 15
    bw = width / len(counts)
    top = counts.max()
    bars = "".join(
        f'<rect x="{k * bw + 0.5:.1f}" y="{plot_h - plot_h * c / top:.1f}" width="{bw - 1:.1f}" height="{plot_h * c / top:.1f}"><title>{c} layouts in [{edges[k]:.4g}, {edges[k + 1]:.4g}] J s</title></rect>'
        for k, c in enumerate(counts))
    return (f'<svg class="hist" width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" '
            f'aria-label="histogram of effort over {len(v)} layouts">{bars}'
            f'<text x="0" y="{height - 1}">{lo:.3g}</text><text x="{width}" y="{height - 1}" text-anchor="end">{hi:.3g}</text></svg>')


def risk_svg(sigmas, risks, mark: float | None = None, low=None, high=None, width: int = 220, height: int = 92) -> str:
    """Risk over sigma as inline SVG on one axis for every trial, 0 to 1 (a risk of
    0.05, one fall in 20, stays near the floor), x over the run's sigma grid; the
    95% Wilson interval of each point (`low`, `high`) as a shaded band; `mark`: the
    sigma of the pairs (a dashed line)."""
    s = np.asarray(sigmas, dtype=float)
    r = np.asarray(risks, dtype=float)
    left, bottom, top = 24, 16, 6
    pw, ph = width - left - 8, height - bottom - top
    s0, s1 = float(s.min()), float(s.max())
    span = s1 - s0 if s1 > s0 else 1.0

    def X(x):
        return left + pw * ((x - s0) / span if s1 > s0 else 0.5)

    def Y(y):
        return top + ph * (1 - y)

    band = ""
    if low is not None and high is not None:
        lo, hi = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        if len(s) == 1:  # one sigma: the interval as a bar
            band = f'<rect class="band" x="{X(s[0]) - 4:.1f}" y="{Y(hi[0]):.1f}" width="8" height="{Y(lo[0]) - Y(hi[0]):.1f}"/>'
        else:
            ring = [(X(a), Y(b)) for a, b in zip(s, hi)] + [(X(a), Y(b)) for a, b in zip(s[::-1], lo[::-1])]
            band = '<polygon class="band" points="' + " ".join(f"{x:.1f},{y:.1f}" for x, y in ring) + '"/>'
    pts = " ".join(f"{X(a):.1f},{Y(b):.1f}" for a, b in zip(s, r))
    dots = "".join(f'<circle cx="{X(a):.1f}" cy="{Y(b):.1f}" r="2.2"><title>sigma {a:g} d: risk {b:.2f}</title></circle>'
                   for a, b in zip(s, r))
    marker = ""
    if mark is not None and s0 <= mark <= s1:
        marker = f'<line class="mark" x1="{X(mark):.1f}" x2="{X(mark):.1f}" y1="{top}" y2="{top + ph}"/>'
    grid = "".join(f'<line class="grid" x1="{left}" x2="{left + pw}" y1="{Y(g):.1f}" y2="{Y(g):.1f}"/>' for g in (0.5,))
    return (f'<svg class="risk" width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" '
            f'aria-label="risk over sigma, axis 0 to 1" data-ymin="0" data-ymax="1">'
            f'<rect class="frame" x="{left}" y="{top}" width="{pw}" height="{ph}"/>{grid}{band}{marker}'
            f'<polyline points="{pts}"/>{dots}'
            f'<text x="{left - 3}" y="{top + 8}" text-anchor="end">1</text>'
            f'<text x="{left - 3}" y="{Y(0.5) + 4:.1f}" text-anchor="end">0.5</text>'
            f'<text x="{left - 3}" y="{top + ph}" text-anchor="end">0</text>'
            f'<text x="{left}" y="{height - 2}">{s0:g}</text><text x="{left + pw}" y="{height - 2}" text-anchor="end">{s1:g} d</text></svg>')

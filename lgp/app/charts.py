"""The results page's small charts as inline SVG (no picture files, no library):
a histogram of effort over layouts and a risk curve over sigma, one of each per
trial card."""
from __future__ import annotations

import numpy as np


def histogram_svg(values, width: int = 150, height: int = 44, bins: int = 10) -> str:
    """A tiny histogram of `values` as inline SVG (axis: min and max printed below)."""
    v = np.asarray(values, dtype=float)
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < 1e-12 * max(1.0, abs(hi)):
        counts, edges = np.array([len(v)]), np.array([lo, hi])
    else:
        counts, edges = np.histogram(v, bins=bins, range=(lo, hi))
    plot_h = height - 12
    bw = width / len(counts)
    top = counts.max()
    bars = "".join(
        f'<rect x="{k * bw + 0.5:.1f}" y="{plot_h - plot_h * c / top:.1f}" width="{bw - 1:.1f}" height="{plot_h * c / top:.1f}"><title>{c} layouts in [{edges[k]:.4g}, {edges[k + 1]:.4g}] J s</title></rect>'
        for k, c in enumerate(counts))
    return (f'<svg class="hist" width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" '
            f'aria-label="histogram of effort over {len(v)} layouts">{bars}'
            f'<text x="0" y="{height - 1}">{lo:.3g}</text><text x="{width}" y="{height - 1}" text-anchor="end">{hi:.3g}</text></svg>')


def risk_svg(sigmas, risks, mark: float | None = None, width: int = 170, height: int = 70) -> str:
    """Risk over sigma as inline SVG: y from 0 to 1, x over the run's sigma grid."""
    s = np.asarray(sigmas, dtype=float)
    r = np.asarray(risks, dtype=float)
    left, bottom, top = 22, 14, 4
    pw, ph = width - left - 4, height - bottom - top
    s0, s1 = float(s.min()), float(s.max())
    span = s1 - s0 if s1 > s0 else 1.0

    def X(x):
        return left + pw * ((x - s0) / span if s1 > s0 else 0.5)

    def Y(y):
        return top + ph * (1 - y)

    pts = " ".join(f"{X(a):.1f},{Y(b):.1f}" for a, b in zip(s, r))
    dots = "".join(f'<circle cx="{X(a):.1f}" cy="{Y(b):.1f}" r="2"><title>sigma {a:g} d: risk {b:.2f}</title></circle>' for a, b in zip(s, r))
    marker = ""
    if mark is not None and s0 <= mark <= s1:
        marker = f'<line class="mark" x1="{X(mark):.1f}" x2="{X(mark):.1f}" y1="{top}" y2="{top + ph}"/>'
    return (f'<svg class="risk" width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" aria-label="risk over sigma">'
            f'<rect class="frame" x="{left}" y="{top}" width="{pw}" height="{ph}"/>{marker}'
            f'<polyline points="{pts}"/>{dots}'
            f'<text x="{left - 2}" y="{top + 7}" text-anchor="end">1</text><text x="{left - 2}" y="{top + ph}" text-anchor="end">0</text>'
            f'<text x="{left}" y="{height - 2}">{s0:g}</text><text x="{left + pw}" y="{height - 2}" text-anchor="end">{s1:g} d</text></svg>')

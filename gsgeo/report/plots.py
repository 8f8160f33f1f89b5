"""The survey report's figures, drawn with matplotlib and returned as PNG data URIs.

Figures are built with matplotlib's object API (``Figure`` on the non-interactive Agg
canvas, never pyplot), so nothing touches a display or global figure state and a server can
draw reports from several threads. PNG at 200 dpi is sharp on paper and quick to lay out
(WeasyPrint draws an SVG figure's glyph paths one by one: several seconds a report).

Plans are in grid easting/northing (the CRS's units); residual vectors are drawn
exaggerated, with a reference arrow stating the scale.
"""

from __future__ import annotations

import base64
import io
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

# Grid coordinates are shown whole (no "+5.71e6" offset a reader must add back).
DPI = 200
#: Points labelled with their ids (and dH) on a plan at most; beyond, labels would hide it.
MAX_LABELS = 60
#: rc_context sets matplotlib's global rcParams for its duration: one figure at a time, so
#: a server drawing two reports at once never draws with the other's (or default) settings.
_LOCK = threading.Lock()
RC: dict[RcKeyType, Any] = {
    "font.size": 8.0,
    "axes.formatter.useoffset": False, "axes.formatter.limits": (-9, 12),
    "axes.titlesize": 9.0, "axes.labelsize": 8.0, "legend.fontsize": 7.0,
    # Text is drawn as given: a point id "$a_$" is an id, not mathtext (which would fail to
    # parse it, or typeset it as a formula). No figure text here is meant as mathtext.
    "text.parse_math": False, "text.usetex": False}
#: Colours: used control, flagged outlier, excluded, check point, measured point.
COLOURS = {"control": "#1f5fa8", "outlier": "#c0182b", "excluded": "#8a8a8a",
           "check": "#1a8a3a", "point": "#444444"}


@dataclass(frozen=True)
class Vector:
    """One residual on a plan: position (grid units), horizontal residual dE, dN (metres),
    vertical dH (metres or NaN) and how to draw it (a COLOURS key)."""

    id: str
    easting: float
    northing: float
    de: float
    dn: float
    dh: float
    style: str


def _uri(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _nice(x: float) -> float:
    """The 1, 2 or 5 times a power of ten nearest below ``x`` (> 0)."""
    e = math.floor(math.log10(x))
    m = x / 10**e
    return (5.0 if m >= 5 else 2.0 if m >= 2 else 1.0) * 10**e


def residual_plan(vectors: Sequence[Vector], title: str) -> str | None:
    """Horizontal residual vectors on a plan (PNG data URI), None when nothing is plotted.

    Arrows are exaggerated so the longest is about a tenth of the plan's extent; a
    reference arrow states the scale in millimetres. Up to MAX_LABELS points are labelled
    with their id and dH in millimetres.
    """
    v = [x for x in vectors if math.isfinite(x.easting) and math.isfinite(x.northing)]
    if not v:
        return None
    e = np.array([x.easting for x in v])
    n = np.array([x.northing for x in v])
    de = np.nan_to_num(np.array([x.de for x in v]))
    dn = np.nan_to_num(np.array([x.dn for x in v]))
    extent = max(float(np.ptp(e)), float(np.ptp(n)), 1.0)
    longest = float(np.max(np.hypot(de, dn))) if len(v) else 0.0
    exaggeration = 0.1 * extent / longest if longest > 0 else 1.0
    with _LOCK, matplotlib.rc_context(RC):
        fig = _figure(6.3, 5.0)
        ax = fig.add_subplot()
        for style in ("control", "check", "excluded", "outlier"):
            sel = np.array([x.style == style for x in v])
            if not sel.any():
                continue
            label = {"control": "control (used)", "check": "check point",
                     "excluded": "control (excluded)", "outlier": "outlier"}[style]
            marker = "^" if style == "check" else "o"
            ax.scatter(e[sel], n[sel], s=18, marker=marker, color=COLOURS[style], label=label,
                       zorder=3)
            ax.quiver(e[sel], n[sel], de[sel] * exaggeration, dn[sel] * exaggeration,
                      angles="xy", scale_units="xy", scale=1.0, color=COLOURS[style],
                      width=0.004, zorder=4)
        for x, xe, xn in zip(v, e, n, strict=True) if len(v) <= MAX_LABELS else ():
            dh = "" if not math.isfinite(x.dh) else f" dH {x.dh * 1000:+.1f}"
            ax.annotate(f"{x.id}{dh}", (xe, xn), xytext=(4, -9), textcoords="offset points",
                        fontsize=6.5, color="#222222")
        if longest > 0:
            ref = _nice(longest)
            x0 = float(e.min())
            y0 = float(n.min()) - 0.12 * extent
            ax.quiver([x0], [y0], [ref * exaggeration], [0.0], angles="xy", scale_units="xy",
                      scale=1.0, color="black", width=0.004)
            ax.annotate(f"{ref * 1000:g} mm (× {exaggeration:.3g})", (x0, y0), xytext=(0, 5),
                        textcoords="offset points", fontsize=7)
        pad = 0.15 * extent
        ax.set_xlim(float(e.min()) - pad, float(e.max()) + pad)
        ax.set_ylim(float(n.min()) - 0.2 * extent, float(n.max()) + pad)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("easting")
        ax.set_ylabel("northing")
        ax.ticklabel_format(useOffset=False, style="plain")
        ax.grid(True, linewidth=0.3, alpha=0.5)
        ax.set_title(title)
        ax.legend(loc="upper right")
        return _uri(fig)


def height_residuals(ids: Sequence[str], dh: Sequence[float], styles: Sequence[str],
                     title: str) -> str | None:
    """dH per point as bars in millimetres (PNG data URI); None without any height."""
    vals = np.array([math.nan if x is None else float(x) for x in dh], dtype=float)
    ok = np.isfinite(vals)
    if not ok.any():
        return None
    with _LOCK, matplotlib.rc_context(RC):
        fig = _figure(6.3, 2.4)
        ax = fig.add_subplot()
        idx = np.nonzero(ok)[0]
        # one collection of bars (vertical lines as wide as a bar), not an artist per point
        width_pt = 0.8 * 400.0 / max(idx.size, 1)
        ax.vlines(np.arange(idx.size), 0.0, vals[idx] * 1000, linewidth=max(width_pt, 0.3),
                  colors=[COLOURS.get(styles[int(i)], COLOURS["point"]) for i in idx],
                  capstyle="butt")
        ax.set_xlim(-0.6, idx.size - 0.4)
        ax.axhline(0.0, color="black", linewidth=0.6)
        if idx.size <= MAX_LABELS:
            ax.set_xticks(np.arange(idx.size), [str(ids[int(i)]) for i in idx], rotation=90,
                          fontsize=6.5)
        else:
            ax.set_xticks([])
        ax.set_ylabel("dH [mm]")
        ax.grid(True, axis="y", linewidth=0.3, alpha=0.5)
        ax.set_title(title)
        return _uri(fig)


def points_plan(ids: Sequence[str], easting: Sequence[float], northing: Sequence[float],
                sigma_e: Sequence[float | None], sigma_n: Sequence[float | None],
                title: str) -> str | None:
    """The measured points on a plan, coloured by horizontal 1-sigma (mm); ids are written
    when there are at most MAX_LABELS points. None without points."""
    e = np.array(easting, dtype=float)
    n = np.array(northing, dtype=float)
    if not e.size:
        return None
    s = np.array([math.nan if a is None or b is None else math.hypot(a, b) * 1000
                  for a, b in zip(sigma_e, sigma_n, strict=True)], dtype=float)
    with _LOCK, matplotlib.rc_context(RC):
        fig = _figure(6.3, 4.6)
        ax = fig.add_subplot()
        finite = s[np.isfinite(s)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if hi - lo < 0.1:  # (nearly) equal sigmas: a readable scale around them
            lo, hi = lo - 0.5, hi + 0.5
        sc = ax.scatter(e, n, c=s, s=10 if e.size > 200 else 18, cmap="viridis", zorder=3,
                        vmin=lo, vmax=hi)
        fig.colorbar(sc, ax=ax, label="horizontal σ (sqrt(σE² + σN²)) [mm]", shrink=0.8)
        if e.size <= MAX_LABELS:
            for i, xe, xn in zip(ids, e, n, strict=True):
                ax.annotate(str(i), (xe, xn), xytext=(3, 3), textcoords="offset points",
                            fontsize=6.5)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("easting")
        ax.set_ylabel("northing")
        ax.ticklabel_format(useOffset=False, style="plain")
        ax.grid(True, linewidth=0.3, alpha=0.5)
        ax.set_title(title)
        return _uri(fig)

"""Line plots as SVG text, for the HTML reports.

A figure is a few axes side by side; an axes takes the calls the reports need, with the
names and meanings of matplotlib's (plot, axhline, axvspan, fill_between, bar, log y,
equal aspect, legend) so a reader of one reads the other. Limits are autoscaled to
everything drawn with a 5 % margin; ticks are 1, 2, 2.5 or 5 times a power of ten, at
most eight across and six up.

Hand-written rather than matplotlib or pygal because a report is drawn at the end of every
plan and `hil run` pays for it (measured with ``python -m bench session``'s
hil_run_startup and by hand, this machine, 2026-11-24): importing matplotlib's Figure and
Agg canvas took 0.28 s of a 0.54 s `hil run` of a two-period plan, and each PNG 33 ms;
pygal imports in 35 ms but rendered 2,000 points in 117 ms and 570 kB. This module imports
in about a millisecond, draws a 4,000-point check figure in a few, and the SVG stays
sharp when zoomed. `hil log plot` and the sweep pages keep matplotlib (no start-up cost
there that a run pays).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: matplotlib's default colour cycle (tab10), so plots look the same as before.
CYCLE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
         "#7f7f7f", "#bcbd22", "#17becf")
DPI = 96
FONT = "font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif"
_DASH = {"-": "", "--": ' stroke-dasharray="5,3"', ":": ' stroke-dasharray="1.5,2"'}


def escape(text: str) -> str:
    """html.escape(text): &, <, >, " and ' as character references. Written out because the
    html package also imports html.entities (2,231 named references, for unescape): ~8 M
    instructions of every `hil run`'s start for a function of five replaces
    (tests/test_report_svg.py holds the two equal)."""
    return (text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;").replace("'", "&#x27;"))


def nice_ticks(lo: float, hi: float, max_ticks: int = 8) -> list[float]:
    """Tick values in [lo, hi]: the smallest step of 1, 2, 2.5 or 5 times a power of ten that
    gives at most `max_ticks` of them."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    power = 10.0 ** math.floor(math.log10((hi - lo) / max_ticks))
    for step in (m * power for m in (1.0, 2.0, 2.5, 5.0, 10.0, 20.0)):
        first = math.ceil(lo / step - 1e-9)
        last = math.floor(hi / step + 1e-9)
        if last - first + 1 <= max_ticks:
            return [k * step for k in range(first, last + 1)]
    return [lo, hi]


def tick_label(value: float, step: float) -> str:
    """A tick's text with as many decimals as the step needs (no '0.30000000000000004')."""
    if value == 0.0:
        return "0"
    magnitude = max(abs(value), abs(step))
    if magnitude >= 1e5 or magnitude < 1e-3:
        return f"{value:.3g}".replace("e-0", "e-").replace("e+0", "e")
    # 1e-6: a step taken as the difference of two large ticks carries their rounding
    decimals = next((d for d in range(13) if abs(round(step, d) - step) <= 1e-6 * abs(step)), 12)
    return f"{value:.{decimals}f}"


def tick_labels(ticks: Sequence[float]) -> list[str]:
    """The texts of evenly spaced ticks: tick_label's, with decimals added until no two are
    equal (a step far below the values' magnitude, 10.0400 .. 10.0401, needs more than the
    .3g the large or tiny magnitudes get)."""
    step = ticks[1] - ticks[0] if len(ticks) > 1 else 1.0
    texts = [tick_label(t, step) for t in ticks]
    digits = 4
    while len(set(texts)) < len(texts) and digits <= 17:
        texts = ["0" if t == 0.0 else f"{t:.{digits}g}" for t in ticks]
        digits += 1
    return texts


def _points(px: np.ndarray, py: np.ndarray) -> list[str]:
    """SVG point lists, split where a value is not finite (a gap, as matplotlib draws it)."""
    ok = np.isfinite(px) & np.isfinite(py)
    runs, start = [], None
    for i, good in enumerate(np.append(ok, False)):
        if good and start is None:
            start = i
        elif not good and start is not None:
            runs.append((start, i))
            start = None
    return [" ".join(f"{a:.1f},{b:.1f}" for a, b in zip(px[s:e], py[s:e])) for s, e in runs]


class Axes:
    """One plotting area at (left, top, width, height) pixels of its figure."""

    def __init__(self, left: float, top: float, width: float, height: float, index: int = 0):
        self.box = (left, top, width, height)
        self.index = index                 # names its clip path within the figure
        self._items: list[tuple] = []      # (kind, data..., style)
        self._zorder: dict[int, float] = {}  # item index -> zorder, where not 2
        self._x: list[np.ndarray] = []     # data extents for autoscaling
        self._y: list[np.ndarray] = []
        self._legend: dict[str, tuple[str, str, float]] = {}
        self._colors = 0
        self.xlabel = self.ylabel = ""
        self.log_y = False
        self.equal = False
        self.show_grid = False
        self.show_legend = False

    # ---------------------------------------------------------------- drawing calls
    def _next_color(self, color: str | None) -> str:
        if color is not None:
            return color
        color = CYCLE[self._colors % len(CYCLE)]
        self._colors += 1
        return color

    def _label(self, label: str | None, color: str, ls: str, alpha: float = 1.0) -> None:
        if label:
            self._legend.setdefault(label, (color, ls, alpha))

    def plot(self, x, y, lw: float = 1.0, label: str | None = None, color: str | None = None,
             ls: str = "-", zorder: float = 2.0) -> None:
        """A line; a higher `zorder` is drawn later, above the others (matplotlib's zorder:
        everything else is at 2), while the legend keeps the order of the calls."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        color = self._next_color(color)
        self._items.append(("line", x, y, color, lw, ls))
        self._zorder[len(self._items) - 1] = zorder
        self._x.append(x)
        self._y.append(y)
        self._label(label, color, ls)

    def axhline(self, y: float, color: str = "#57606a", lw: float = 1.0, ls: str = "-",
                label: str | None = None) -> None:
        self._items.append(("hline", float(y), color, lw, ls))
        self._y.append(np.array([y], dtype=float))
        self._label(label, color, ls)

    def axvline(self, x: float, color: str = "#57606a", lw: float = 1.0, ls: str = "-",
                label: str | None = None) -> None:
        self._items.append(("vline", float(x), color, lw, ls))
        self._x.append(np.array([x], dtype=float))
        self._label(label, color, ls)

    def axhspan(self, y0: float, y1: float, color: str, alpha: float = 0.1,
                label: str | None = None) -> None:
        self._items.append(("hspan", float(y0), float(y1), color, alpha))
        self._y.append(np.array([y0, y1], dtype=float))
        self._label(label, color, "span", alpha)

    def axvspan(self, x0: float, x1: float, color: str, alpha: float = 0.1,
                label: str | None = None) -> None:
        self._items.append(("vspan", float(x0), float(x1), color, alpha))
        self._x.append(np.array([x0, x1], dtype=float))
        self._label(label, color, "span", alpha)

    def fill_between(self, x, lo, hi, color: str, alpha: float = 0.15, step: str | None = None,
                     label: str | None = None) -> None:
        """The band between `lo` and `hi`; step="mid" draws each value as a flat step centred
        on its x (as matplotlib's step="mid")."""
        x, lo, hi = (np.asarray(v, dtype=float) for v in (x, lo, hi))
        if step == "mid" and len(x) > 1:
            edges = np.concatenate([[x[0]], (x[:-1] + x[1:]) / 2.0, [x[-1]]])
            x = np.repeat(edges, 2)[1:-1]
            lo, hi = np.repeat(lo, 2), np.repeat(hi, 2)
        self._items.append(("band", x, lo, hi, color, alpha))
        self._x.append(x)
        self._y.extend([lo, hi])
        self._label(label, color, "span", alpha)

    def bar(self, x, heights, color: str | None = None, width: float = 0.8) -> None:
        x, heights = np.asarray(x, dtype=float), np.asarray(heights, dtype=float)
        color = self._next_color(color)
        self._items.append(("bars", x, heights, color, width))
        self._x.append(np.concatenate([x - width / 2, x + width / 2]))
        self._y.append(heights)

    def annotate_mark(self, text: str, x: float, color: str = "#57606a") -> None:
        """A name written upwards at the top of the axes beside x (a plan's mark)."""
        self._items.append(("mark", float(x), text, color))

    def set_xlabel(self, text: str) -> None:
        self.xlabel = text

    def set_ylabel(self, text: str) -> None:
        self.ylabel = text

    def set_yscale(self, scale: str) -> None:
        self.log_y = scale == "log"

    def set_aspect(self, aspect: str) -> None:
        self.equal = aspect == "equal"

    def grid(self, on: bool = True, lw: float = 0.3) -> None:
        self.show_grid = on

    def legend(self) -> None:
        self.show_legend = True

    # ---------------------------------------------------------------- rendering
    def _limits(self) -> tuple[float, float, float, float]:
        def extent(parts: list[np.ndarray], log: bool) -> tuple[float, float]:
            values = np.concatenate(parts) if parts else np.array([])
            values = values[np.isfinite(values)]
            if log:
                values = values[values > 0]
            if values.size == 0:
                return (1.0, 10.0) if log else (0.0, 1.0)
            lo, hi = float(values.min()), float(values.max())
            if log:
                return 10.0 ** math.floor(math.log10(lo)), 10.0 ** math.ceil(math.log10(hi) + 1e-12)
            if hi == lo:
                pad = abs(lo) * 0.05 or 0.5
                return lo - pad, hi + pad
            pad = 0.05 * (hi - lo)
            return lo - pad, hi + pad

        x0, x1 = extent(self._x, False)
        y0, y1 = extent(self._y, self.log_y)
        if self.equal and not self.log_y:
            _, _, w, h = self.box
            scale = max((x1 - x0) / w, (y1 - y0) / h)   # data units per pixel, the larger
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            x0, x1 = cx - scale * w / 2, cx + scale * w / 2
            y0, y1 = cy - scale * h / 2, cy + scale * h / 2
        return x0, x1, y0, y1

    def render(self) -> str:
        left, top, w, h = self.box
        x0, x1, y0, y1 = self._limits()
        if self.log_y:
            ly0, ly1 = math.log10(y0), math.log10(y1)

            def ypix(v):
                v = np.asarray(v, dtype=float)
                with np.errstate(divide="ignore", invalid="ignore"):
                    return top + h - (np.log10(np.where(v > 0, v, np.nan)) - ly0) / (ly1 - ly0) * h
        else:
            def ypix(v):
                return top + h - (np.asarray(v, dtype=float) - y0) / (y1 - y0) * h

        def xpix(v):
            return left + (np.asarray(v, dtype=float) - x0) / (x1 - x0) * w

        out = [f'<clipPath id="clip{self.index}"><rect x="{left:.1f}" y="{top:.1f}" width="{w:.1f}" '
               f'height="{h:.1f}"/></clipPath>']
        clip = f'clip-path="url(#clip{self.index})"'
        xticks = nice_ticks(x0, x1)
        if self.log_y:
            yticks = [10.0 ** k for k in range(round(math.log10(y0)), round(math.log10(y1)) + 1)]
        else:
            yticks = nice_ticks(y0, y1, 6)
        if self.show_grid:
            grid = [f'M{float(xpix(t)):.1f} {top:.1f}V{top + h:.1f}' for t in xticks]
            grid += [f'M{left:.1f} {float(ypix(t)):.1f}H{left + w:.1f}' for t in yticks]
            out.append(f'<path d="{" ".join(grid)}" stroke="#d0d7de" stroke-width="0.5" fill="none"/>')
        body = []
        drawn: list[tuple[np.ndarray, np.ndarray]] = []    # line pixels, to place the legend
        order = sorted(range(len(self._items)), key=lambda i: self._zorder.get(i, 2.0))
        for item in (self._items[i] for i in order):
            kind = item[0]
            if kind == "line":
                _, x, y, color, lw, ls = item
                drawn.append((xpix(x), ypix(y)))
                for pts in _points(*drawn[-1]):
                    body.append(f'<polyline points="{pts}" fill="none" stroke="{color}" '
                                f'stroke-width="{lw * 1.33:.2f}"{_DASH.get(ls, "")}/>')
            elif kind == "hline":
                _, y, color, lw, ls = item
                py = float(ypix(y))
                body.append(f'<path d="M{left:.1f} {py:.1f}H{left + w:.1f}" stroke="{color}" '
                            f'stroke-width="{lw * 1.33:.2f}"{_DASH.get(ls, "")}/>')
            elif kind == "vline":
                _, x, color, lw, ls = item
                px = float(xpix(x))
                body.append(f'<path d="M{px:.1f} {top:.1f}V{top + h:.1f}" stroke="{color}" '
                            f'stroke-width="{lw * 1.33:.2f}"{_DASH.get(ls, "")}/>')
            elif kind == "hspan":
                _, a, b, color, alpha = item
                pa, pb = sorted((float(ypix(a)), float(ypix(b))))
                body.append(f'<rect x="{left:.1f}" y="{pa:.1f}" width="{w:.1f}" height="{pb - pa:.1f}" '
                            f'fill="{color}" fill-opacity="{alpha}"/>')
            elif kind == "vspan":
                _, a, b, color, alpha = item
                pa, pb = sorted((float(xpix(a)), float(xpix(b))))
                body.append(f'<rect x="{pa:.1f}" y="{top:.1f}" width="{pb - pa:.1f}" height="{h:.1f}" '
                            f'fill="{color}" fill-opacity="{alpha}"/>')
            elif kind == "band":
                _, x, lo, hi, color, alpha = item
                px = xpix(np.concatenate([x, x[::-1]]))
                py = ypix(np.concatenate([hi, lo[::-1]]))
                for pts in _points(px, py):
                    body.append(f'<polygon points="{pts}" fill="{color}" fill-opacity="{alpha}"/>')
            elif kind == "bars":
                _, x, heights, color, width = item
                base = y0 if self.log_y else 0.0
                for xc, hv in zip(x, heights):
                    if not math.isfinite(hv) or (self.log_y and hv <= 0):
                        continue
                    pa, pb = float(xpix(xc - width / 2)), float(xpix(xc + width / 2))
                    ya, yb = sorted((float(ypix(hv)), float(ypix(base))))
                    body.append(f'<rect x="{pa:.1f}" y="{ya:.1f}" width="{pb - pa:.1f}" '
                                f'height="{yb - ya:.1f}" fill="{color}"/>')
            elif kind == "mark":
                _, x, text, color = item
                px = float(xpix(x))
                body.append(f'<text transform="translate({px - 3:.1f},{top + 4:.1f}) rotate(-90)" '
                            f'text-anchor="end" font-size="9" fill="{color}">{escape(text)}</text>')
        out.append(f'<g {clip}>{"".join(body)}</g>')
        out.append(f'<rect x="{left:.1f}" y="{top:.1f}" width="{w:.1f}" height="{h:.1f}" '
                   f'fill="none" stroke="#57606a" stroke-width="0.8"/>')
        for t, text in zip(xticks, tick_labels(xticks)):
            px = float(xpix(t))
            out.append(f'<path d="M{px:.1f} {top + h:.1f}v4" stroke="#57606a"/><text x="{px:.1f}" '
                       f'y="{top + h + 15:.1f}" text-anchor="middle" font-size="10">'
                       f'{text}</text>')
        ylabels = [f"{t:g}" for t in yticks] if self.log_y else tick_labels(yticks)
        for t, text in zip(yticks, ylabels):
            py = float(ypix(t))
            out.append(f'<path d="M{left:.1f} {py:.1f}h-4" stroke="#57606a"/><text x="{left - 6:.1f}" '
                       f'y="{py + 3.5:.1f}" text-anchor="end" font-size="10">{text}</text>')
        if self.xlabel:
            out.append(f'<text x="{left + w / 2:.1f}" y="{top + h + 31:.1f}" text-anchor="middle" '
                       f'font-size="11">{escape(self.xlabel)}</text>')
        if self.ylabel:
            out.append(f'<text transform="translate({left - 52:.1f},{top + h / 2:.1f}) rotate(-90)" '
                       f'text-anchor="middle" font-size="11">{escape(self.ylabel)}</text>')
        if self.show_legend and self._legend:
            out.append(self._render_legend(drawn))
        return "".join(out)

    def _render_legend(self, drawn: list[tuple[np.ndarray, np.ndarray]]) -> str:
        """The legend in the corner that hides the fewest line points (matplotlib's "best",
        over the four corners; upper right on a tie)."""
        left, top, w, h = self.box
        rows = list(self._legend.items())
        width = 30 + 6.0 * max(len(label) for label, _ in rows)
        height = 8 + 13 * len(rows)
        px = np.concatenate([p[0] for p in drawn]) if drawn else np.array([])
        py = np.concatenate([p[1] for p in drawn]) if drawn else np.array([])

        def hidden(corner: tuple[float, float]) -> int:
            cx, cy = corner
            return int(np.count_nonzero((px >= cx) & (px <= cx + width) &
                                        (py >= cy) & (py <= cy + height)))

        corners = [(left + w - width - 6, top + 6), (left + 6, top + 6),
                   (left + w - width - 6, top + h - height - 6), (left + 6, top + h - height - 6)]
        x, y = min(corners, key=hidden)
        out = [f'<rect x="{x:.1f}" y="{y:.1f}" width="{width:.1f}" height="{height}" '
               f'fill="#ffffff" fill-opacity="0.85" stroke="#d0d7de"/>']
        for i, (label, (color, ls, alpha)) in enumerate(rows):
            cy = y + 11 + 13 * i
            if ls == "span":
                out.append(f'<rect x="{x + 5:.1f}" y="{cy - 4:.1f}" width="16" height="8" '
                           f'fill="{color}" fill-opacity="{max(alpha, 0.25)}"/>')
            else:
                out.append(f'<path d="M{x + 5:.1f} {cy:.1f}h16" stroke="{color}" '
                           f'stroke-width="1.5"{_DASH.get(ls, "")}/>')
            out.append(f'<text x="{x + 25:.1f}" y="{cy + 3.5:.1f}" font-size="9">{escape(label)}</text>')
        return "".join(out)


class Figure:
    """`ncols` axes side by side in a width x height inch figure, with fixed margins (inches:
    0.75 left, 0.5 bottom, 0.35 top, 0.15 right, 0.3 of an axes' width between axes)."""

    def __init__(self, width_in: float = 7.5, height_in: float = 3.0, ncols: int = 1):
        self.width, self.height = width_in * DPI, height_in * DPI
        left, right, top, bottom = 0.75 * DPI, 0.15 * DPI, 0.35 * DPI, 0.5 * DPI
        span = self.width - left - right
        axes_w = span / (ncols + 0.3 * (ncols - 1))
        self.axes = [Axes(left + i * 1.3 * axes_w, top, axes_w, self.height - top - bottom, i)
                     for i in range(ncols)]
        self.title = ""
        self.title_color = "#1f2328"

    def suptitle(self, text: str, color: str | None = None) -> None:
        self.title = text
        self.title_color = color or self.title_color

    def svg(self, alt: str = "") -> str:
        """The figure as one SVG document (its clip-path ids are unique only within it, so a
        page embeds it as an image, not inline)."""
        parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{self.width:.0f}" '
                 f'height="{self.height:.0f}" viewBox="0 0 {self.width:.0f} {self.height:.0f}" '
                 f'role="img" aria-label="{escape(alt)}" style="{FONT}">',
                 f'<rect width="100%" height="100%" fill="#ffffff"/>']
        if self.title:
            parts.append(f'<text x="{self.width / 2:.1f}" y="18" text-anchor="middle" font-size="12" '
                         f'fill="{self.title_color}">{escape(self.title)}</text>')
        parts.extend(ax.render() for ax in self.axes)
        parts.append("</svg>")
        return "".join(parts)


def polyline_points(svg: str) -> list[list[tuple[float, float]]]:
    """The point lists of every <polyline> in `svg` (for tests and tools reading a figure)."""
    import re

    return [[tuple(map(float, p.split(","))) for p in pts.split()]
            for pts in re.findall(r'<polyline points="([^"]*)"', svg)]


__all__: Sequence[str] = ("Axes", "Figure", "nice_ticks", "tick_label", "tick_labels",
                          "polyline_points")

"""The sorting line's dashboard, drawn headless with matplotlib's Agg renderer.

One :class:`DashboardFrame` describes one tick of one line; :func:`render_dashboard` turns it into
an RGB array (``render_mode="rgb_array"``), :func:`save_dashboard` writes it as PNG or SVG, and
:class:`LiveDashboard` shows it in one window that is updated in place (``render_mode="human"``).

The layout follows the reference implementation's dashboard (a 2 x 4 grid: input, belt, sorting
machine, containers; belt status, per-step series, cumulative reward, KPIs) with its defects fixed:
the container labels are the real purity of each container (correct material / all material in
that container), not the share of a material that was sorted correctly, and the foreign material
in a container is drawn as what it is (the other material, hatched).

Figures are built from ``matplotlib.figure.Figure`` and drawn by ``FigureCanvasAgg`` directly, so
rendering neither needs nor touches pyplot, its current figure or the selected backend. Only
:class:`LiveDashboard` imports pyplot, lazily, when it first shows a frame.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

# MODE_NAMES: the advanced line's sort modes by number. START_SPEED: the belt speed after a reset,
# which the first step's speed is compared with (as the line's penalty does).
from ..line.vocabulary import MODE_LABELS as MODE_NAMES
from ..line.vocabulary import START_SPEED, VARIANTS

__all__ = [
    "DashboardFrame",
    "LiveDashboard",
    "MODE_NAMES",
    "START_SPEED",
    "count_speed_changes",
    "render_dashboard",
    "save_dashboard",
]


# Reference pixel size: every size below is tuned for 1600 x 800 and scales with the output.
BASE_WIDTH_PX = 1600
BASE_HEIGHT_PX = 800
_BASE_DPI = 100.0

# Colours: material A blue, material B orange (the same in every panel); one colour per metric,
# shared by the belt-status bars and the series plot.
COLOR_A = "#1f77b4"
COLOR_B = "#ff7f0e"
COLOR_REWARD = "#222222"
COLOR_SPEED = "#9467bd"
COLOR_ACCURACY = "#2ca02c"
COLOR_OCCUPANCY = "#8c564b"
COLOR_MODE = "#7f7f7f"
COLOR_LIMIT = "#d62728"
COLOR_CUMULATIVE = "#17becf"

# Font sizes in points at the reference size.
_FS_SUPTITLE = 15
_FS_TITLE = 11.5
_FS_LABEL = 10
_FS_TICK = 9
_FS_ANNOT = 9.5
_FS_LEGEND = 8.5
_FS_KPI = 11

# Text styles: a panel's title (the figure-level panels' are placed like the Axes titles and look the
# same; no mathtext, a "$" stays a "$") and a note a panel shows next to its plot.
_TITLE_STYLE = {"fontsize": _FS_TITLE, "parse_math": False}
_NOTE_STYLE = {"fontsize": _FS_ANNOT, "fontweight": "bold"}


@dataclass
class DashboardFrame:
    """One tick of one line, everything the dashboard shows."""

    variant: str  # "basic" | "advanced"
    title: str  # e.g. "SortingLine-v0 setup B, seed 42, episode 3"
    input_ab: tuple[int, int]  # next batch (A, B) units
    belt_ab: tuple[int, int]  # batch on the belt
    machine_ab: tuple[int, int]  # batch in the sorting machine
    # (a_correct, a_wrong, b_correct, b_wrong): container A holds a_correct of A plus b_wrong of B;
    # container B holds b_correct of B plus a_wrong of A.
    containers: tuple[int, int, int, int]
    belt_accuracy: float  # accuracy computed for the belt batch this tick
    sorter_accuracy: float  # accuracy the machine's batch is sorted with
    occupancy: float  # belt occupancy 0..1
    speed: float  # 0.1..1.0
    mode: int | None  # advanced: 0 basic, 1 positive (A-rich), 2 negative (B-rich)
    purity: float  # container purity, correct / all sorted
    history_reward: list[float]  # per step of this episode so far
    history_speed: list[float]
    history_accuracy: list[float]
    history_occupancy: list[float]
    history_mode: list[int] | None
    max_steps: int  # x-axis length of the series plots (e.g. 50)


# ------------------------------------------------------------------------------------------------
# public API
# ------------------------------------------------------------------------------------------------


def render_dashboard(frame: DashboardFrame, *, width_px: int = 1600, height_px: int = 800) -> np.ndarray:
    """The dashboard as an (height_px, width_px, 3) uint8 RGB array.

    Deterministic: the same frame (and the same matplotlib rcParams) gives the same array.
    """
    fig = _build_figure(frame, width_px, height_px)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    return _fit(rgba[..., :3], height_px, width_px)


def save_dashboard(frame: DashboardFrame, path: str | os.PathLike) -> None:
    """Writes the dashboard at the reference size (1600 x 800 px); PNG or SVG by the file suffix."""
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "svg"):
        raise ValueError(f"save_dashboard: unsupported file type {path.suffix!r} for {path} (use .png or .svg)")
    fig = _build_figure(frame, BASE_WIDTH_PX, BASE_HEIGHT_PX)
    FigureCanvasAgg(fig)  # a canvas without pyplot; savefig switches to the SVG canvas by itself
    if fmt == "svg":
        import matplotlib

        # Fixed element ids and no date: the same frame gives the same file.
        with matplotlib.rc_context({"svg.hashsalt": "sorting_line"}):
            fig.savefig(path, format="svg", metadata={"Date": None})
    else:
        fig.savefig(path, format="png", dpi=fig.dpi)


class LiveDashboard:
    """One window, updated in place on every :meth:`show` (``render_mode="human"``).

    Frames are rendered off-screen with :func:`render_dashboard` and shown as an image, so the
    window is exactly the rgb_array output. pyplot is imported only here, on the first show. When
    no interactive backend can be used (no display, headless CI), show() warns once and then does
    nothing.
    """

    def __init__(self) -> None:
        self._plt = None
        self._fig = None
        self._image = None
        self._disabled = False

    def show(self, frame: DashboardFrame) -> None:
        if self._disabled:
            return
        try:
            plt = self._pyplot()
        except Exception as e:  # e.g. a backend that cannot start without a display
            self._disable(f"cannot start the live dashboard ({type(e).__name__}: {e})", stacklevel=3)
            return
        if plt is None:
            return
        rgb = render_dashboard(frame)  # outside the try: a rendering bug must not pass as a display problem
        try:
            if self._fig is None or not plt.fignum_exists(self._fig.number):
                self._open(plt, rgb)  # first call, or the user closed the window: (re)open it
            else:
                self._image.set_data(rgb)
            self._fig.canvas.manager.set_window_title(frame.title or "sorting line")
            self._fig.canvas.draw_idle()
            plt.pause(0.001)
        except Exception as e:  # a broken or vanished display must not stop the environment
            self._disable(f"cannot show the live dashboard ({type(e).__name__}: {e})", stacklevel=3)

    def close(self) -> None:
        if self._fig is not None and self._plt is not None:
            try:
                self._plt.close(self._fig)
            except Exception:
                pass
        self._fig = None
        self._image = None

    # --- internals

    def _pyplot(self):
        if self._plt is not None:
            return self._plt
        import matplotlib
        import matplotlib.pyplot as plt
        from matplotlib.backends import BackendFilter, backend_registry

        backend = str(plt.get_backend()).lower()  # resolves the automatic choice (Agg when headless)
        interactive = {b.lower() for b in backend_registry.list_builtin(BackendFilter.INTERACTIVE)}
        if backend not in interactive and not backend.startswith("module://"):
            self._disable(
                f"no interactive matplotlib backend (backend is {matplotlib.get_backend()!r}; "
                "no display?); the live dashboard shows nothing. Use render_mode='rgb_array' "
                "or save_dashboard() instead",
                stacklevel=4,
            )
            return None
        self._plt = plt
        return plt

    def _open(self, plt, rgb: np.ndarray) -> None:
        h, w = rgb.shape[:2]
        self._plt = plt
        self._fig = plt.figure(figsize=(w / _BASE_DPI, h / _BASE_DPI), dpi=_BASE_DPI)
        ax = self._fig.add_axes((0, 0, 1, 1))
        ax.set_axis_off()
        self._image = ax.imshow(rgb, interpolation="antialiased")
        plt.show(block=False)

    def _disable(self, message: str, stacklevel: int) -> None:
        """Warns once (at the caller of show()) and turns show() into a no-op."""
        self._disabled = True
        self.close()
        warnings.warn(message, RuntimeWarning, stacklevel=stacklevel)


def count_speed_changes(history_speed: Sequence[float], start_speed: float = START_SPEED) -> int:
    """Belt-speed changes in an episode: the first step against the start speed, then step to step.

    The same count the line keeps (and the penalty charges); sort-mode changes are not counted.
    """
    changes = 0
    previous = start_speed
    for speed in history_speed:
        if abs(float(speed) - float(previous)) > 1e-6:
            changes += 1
        previous = speed
    return changes


# ------------------------------------------------------------------------------------------------
# figure
#
# Speed matters (live rendering builds a new figure every tick), and with the Agg renderer the cost
# is dominated by Axes, ticks, legends and texts. So: six Axes (the pie and the KPI box are drawn as
# figure-level artists), few explicit ticks, fixed title and label positions (no tight-bbox
# searches), and legends made of plain texts placed next to each other.
# ------------------------------------------------------------------------------------------------


def _build_figure(frame: DashboardFrame, width_px: int, height_px: int) -> Figure:
    if frame.variant not in VARIANTS:
        raise ValueError(f"DashboardFrame.variant must be 'basic' or 'advanced', not {frame.variant!r}")
    width_px, height_px = int(width_px), int(height_px)
    if width_px < 16 or height_px < 8:
        raise ValueError(f"dashboard size {width_px} x {height_px} px is too small")
    # Scale the dpi, not the fonts: the layout keeps its proportions at any size.
    scale = min(width_px / BASE_WIDTH_PX, height_px / BASE_HEIGHT_PX)
    dpi = _BASE_DPI * scale
    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi, facecolor="white")

    fig.text(0.5, 0.975, frame.title, ha="center", va="top", fontsize=_FS_SUPTITLE, fontweight="bold", parse_math=False)

    top = fig.add_gridspec(1, 4, left=0.035, right=0.985, top=0.875, bottom=0.575, wspace=0.28)
    bottom = fig.add_gridspec(
        1, 4, left=0.035, right=0.985, top=0.43, bottom=0.135, wspace=0.22, width_ratios=(0.9, 1.55, 1.1, 0.75)
    )

    _panel_input(fig, top[0, 0].get_position(fig), frame)
    _panel_belt(fig.add_subplot(top[0, 1]), frame)
    _panel_machine(fig.add_subplot(top[0, 2]), frame)
    _panel_containers(fig.add_subplot(top[0, 3]), frame)
    _panel_status(fig.add_subplot(bottom[0, 0]), frame)
    _panel_series(fig.add_subplot(bottom[0, 1]), frame)
    _panel_cumulative(fig.add_subplot(bottom[0, 2]), frame)
    _panel_kpis(fig, bottom[0, 3].get_position(fig), frame)
    return fig


def _fit(rgb: np.ndarray, height: int, width: int) -> np.ndarray:
    """Exactly height x width (the canvas can be a pixel short from float rounding); a copy."""
    if rgb.shape[:2] == (height, width):
        return np.ascontiguousarray(rgb)
    out = np.full((height, width, 3), 255, dtype=np.uint8)
    h, w = min(height, rgb.shape[0]), min(width, rgb.shape[1])
    out[:h, :w] = rgb[:h, :w]
    return out


def _style(ax, title: str) -> None:
    # A fixed title position: matplotlib's automatic one measures every tick label of the Axes.
    ax.set_title(title, pad=6, y=1.0, **_TITLE_STYLE)
    ax.tick_params(labelsize=_FS_TICK)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def _ylabel(ax, text: str) -> None:
    ax.set_ylabel(text, fontsize=_FS_LABEL)
    ax.yaxis.set_label_coords(-0.14, 0.5)


def _xlabel(ax, text: str) -> None:
    ax.set_xlabel(text, fontsize=_FS_LABEL)
    ax.xaxis.set_label_coords(0.5, -0.1)


def _key(ax, x: float, y: float, items, *, fontsize: float = _FS_LEGEND, gap_pt: float = 10.0) -> None:
    """A one-row legend made of texts: per item a coloured symbol and a dark label, each placed
    right of the previous one by matplotlib at draw time (no width guessing, so no overlap).
    (x, y): the row's left end, in axes coordinates (outside the Axes is fine)."""
    prev = None
    for symbol, color, label in items:
        for text, col, offset in ((symbol, color, gap_pt), (label, "#222222", 2.5)):
            if prev is None:
                where = {"xy": (x, y), "xycoords": "axes fraction"}
            else:
                where = {"xy": (1.0, 0.5), "xycoords": prev, "xytext": (offset, 0), "textcoords": "offset points"}
            prev = ax.annotate(
                text, **where, ha="left", va="center", fontsize=fontsize, color=col, annotation_clip=False
            )


def _pair(values: Sequence[int]) -> tuple[int, int]:
    a, b = (max(0, int(v)) for v in values)
    return a, b


def _pct(x: float) -> str:
    """A share as a percentage with one decimal that never rounds to a false 100.0% or 0.0%."""
    x = float(x)
    if not math.isfinite(x):
        return "n/a"
    text = f"{100.0 * x:.1f}%"
    if text == "100.0%" and x < 1.0:
        return ">99.9%"
    if text == "0.0%" and x > 0.0:
        return "<0.1%"
    return text


def _finite(v: float) -> float:
    v = float(v)
    return v if math.isfinite(v) else 0.0


def _fig_title(fig: Figure, x_in: float, top_in: float, text: str) -> None:
    """A panel title for a figure-level panel, placed like an Axes title (baseline 6 pt above the top)."""
    fig.text(x_in, top_in + 6 / 72, text, transform=fig.dpi_scale_trans, ha="center", va="baseline", **_TITLE_STYLE)


def _inches(fig: Figure, box) -> tuple[float, float, float, float]:
    """A figure-fraction Bbox as (x0, y0, width, height) in inches."""
    w_in, h_in = fig.get_size_inches()
    return box.x0 * w_in, box.y0 * h_in, box.width * w_in, box.height * h_in


# --- (1) input: a pie drawn with figure-level patches (in inches, so it stays round)


def _panel_input(fig: Figure, box, frame: DashboardFrame) -> None:
    from matplotlib.patches import Circle, Wedge

    a, b = _pair(frame.input_ab)
    total = a + b
    x0, y0, w, h = _inches(fig, box)
    inch = fig.dpi_scale_trans
    _fig_title(fig, x0 + w / 2, y0 + h, f"Input (next batch): {total} units")
    r = min(w, h) * 0.42
    cx, cy = x0 + w / 2, y0 + h - r - 0.06
    if total == 0:
        fig.add_artist(Circle((cx, cy), r, transform=inch, fill=False, edgecolor="#999999", linestyle="--"))
        fig.text(cx, cy, "no material", transform=inch, ha="center", va="center", fontsize=_FS_ANNOT, color="#666666")
    else:
        start = 90.0  # A from 12 o'clock clockwise, then B
        for count, color, name in ((a, COLOR_A, "A"), (b, COLOR_B, "B")):
            share = count / total
            if share <= 0:
                continue
            end = start - 360.0 * share
            fig.add_artist(
                Wedge((cx, cy), r, end, start, transform=inch, facecolor=color, edgecolor="white", linewidth=1.5)
            )
            if share >= 0.07:  # thinner wedges get no label; the counts below still say it
                mid = math.radians((start + end) / 2)
                d = 0.55 * r if share < 0.999 else 0.0
                fig.text(
                    cx + d * math.cos(mid),
                    cy + d * math.sin(mid),
                    f"{name}\n{100 * share:.0f}%",
                    transform=inch,
                    ha="center",
                    va="center",
                    fontsize=_FS_ANNOT + 1,
                    color="white",
                    fontweight="bold",
                )
            start = end
    ty = cy - r - 0.2
    fig.text(
        cx - 0.1, ty, f"\u25a0 A: {a}", transform=inch, ha="right", va="center", fontsize=_FS_ANNOT + 0.5, color=COLOR_A
    )
    fig.text(
        cx + 0.1, ty, f"\u25a0 B: {b}", transform=inch, ha="left", va="center", fontsize=_FS_ANNOT + 0.5, color=COLOR_B
    )


# --- (2) belt and (3) sorting machine


def _material_bars(ax, a: int, b: int) -> None:
    bars = ax.bar((0, 1), (a, b), color=(COLOR_A, COLOR_B), width=0.6)
    for bar, count in zip(bars, (a, b), strict=False):
        ax.text(bar.get_x() + bar.get_width() / 2, count + 2, str(count), ha="center", va="bottom", fontsize=_FS_ANNOT)
    ax.set_xlim(-0.6, 1.6)
    ax.set_xticks((0, 1), ("A", "B"), fontsize=_FS_LABEL)
    ax.set_ylim(0, 112)
    ax.set_yticks((0, 50, 100))
    _ylabel(ax, "units")


def _panel_belt(ax, frame: DashboardFrame) -> None:
    _panel_stage(ax, "Conveyor belt", frame.belt_ab, f"occupancy {_pct(frame.occupancy)}", COLOR_OCCUPANCY)


def _panel_machine(ax, frame: DashboardFrame) -> None:
    note = f"sorted with accuracy {_pct(frame.sorter_accuracy)}"
    _panel_stage(ax, "Sorting machine", frame.machine_ab, note, COLOR_ACCURACY)


def _panel_stage(ax, name: str, ab: Sequence[int], note: str, color: str) -> None:
    """A stage of the line (belt or sorting machine): its A/B units as bars, `note` top right in `color`."""
    a, b = _pair(ab)
    _style(ax, f"{name}: {a + b} units")
    _material_bars(ax, a, b)
    ax.text(0.99, 0.99, note, transform=ax.transAxes, ha="right", va="top", color=color, **_NOTE_STYLE)


# --- (4) containers


def _panel_containers(ax, frame: DashboardFrame) -> None:
    from matplotlib.ticker import MaxNLocator

    a_ok, a_wrong, b_ok, b_wrong = (max(0, int(v)) for v in frame.containers)
    in_a = a_ok + b_wrong  # container A: correct A plus foreign B
    in_b = b_ok + a_wrong  # container B: correct B plus foreign A
    total = in_a + in_b
    _style(ax, f"Containers: {total} units, purity {_pct(frame.purity) if total else 'n/a'}")

    x = (0, 1)
    correct = (a_ok, b_ok)
    foreign = (b_wrong, a_wrong)
    ax.bar(x, correct, width=0.6, color=(COLOR_A, COLOR_B), edgecolor="white", linewidth=0.8)
    ax.bar(
        x,
        foreign,
        bottom=correct,
        width=0.6,
        color=(COLOR_B, COLOR_A),
        alpha=0.55,
        hatch="///",
        edgecolor="white",
        linewidth=0.8,
    )
    ymax = max(10.0, max(in_a, in_b) * 1.45)
    ax.set_ylim(0, ymax)
    ax.set_xlim(-0.6, 1.6)
    ax.set_xticks(x, ("container A", "container B"), fontsize=_FS_LABEL)
    ax.yaxis.set_major_locator(MaxNLocator(4, integer=True))
    ax.yaxis.set_major_formatter(_compact_units)
    _ylabel(ax, "units")
    for xi, ok, bad in zip(x, correct, foreign, strict=False):
        held = ok + bad
        label = f"purity {_pct(ok / held)}\n{ok} / {held}" if held else "empty"
        ax.text(xi, held + ymax * 0.015, label, ha="center", va="bottom", fontsize=_FS_ANNOT)
    _key(
        ax,
        0.02,
        0.95,
        (("\u25a0", COLOR_A, "A"), ("\u25a0", COLOR_B, "B"), ("\u25a8", "#777777", "foreign (other material)")),
    )


def _compact_units(value: float, _pos=None) -> str:
    """Tick labels that stay short for long runs: 2500, 25k, 1.2M."""
    v = abs(value)
    if v >= 1e6:
        return f"{value / 1e6:.3g}M"
    if v >= 1e4:
        return f"{value / 1e3:.3g}k"
    return f"{value:.0f}"


# --- (5) belt status


def _panel_status(ax, frame: DashboardFrame) -> None:
    title = "Belt status"
    if frame.variant == "advanced":
        title += f"\nmode: {_mode_name(frame.mode)}"
    _style(ax, title)
    values = tuple(_finite(v) for v in (frame.belt_accuracy, frame.occupancy, frame.speed))
    bars = ax.bar((0, 1, 2), values, color=(COLOR_ACCURACY, COLOR_OCCUPANCY, COLOR_SPEED), width=0.6)
    ax.axhline(1.0, color=COLOR_LIMIT, linewidth=1.5, linestyle="--")
    for bar, v in zip(bars, values, strict=False):
        ax.text(
            bar.get_x() + bar.get_width() / 2,
            min(v, 1.0) + 0.03,
            f"{v:.2f}",
            ha="center",
            va="bottom",
            fontsize=_FS_ANNOT,
        )
    ax.set_xlim(-0.6, 2.6)
    ax.set_xticks((0, 1, 2), ("accuracy", "occupancy", "speed"), fontsize=_FS_LABEL - 0.5)
    ax.set_ylim(0, 1.18)
    ax.set_yticks((0, 0.5, 1.0))


def _mode_name(mode: int | None) -> str:
    if mode is None:
        return "n/a"
    return MODE_NAMES.get(int(mode), f"unknown ({mode})")


# --- (6) per-step series


def _x_limit(frame: DashboardFrame, n: int) -> int:
    return max(int(frame.max_steps), n, 1)


def _step_ticks(ax, limit: int) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.set_xlim(0, limit)
    ax.xaxis.set_major_locator(MaxNLocator(6, integer=True))


def _panel_series(ax, frame: DashboardFrame) -> None:
    speeds = np.asarray(frame.history_speed, dtype=float)
    mean_speed = f"{100 * np.nanmean(speeds):.0f}%" if speeds.size else "n/a"
    _style(ax, f"Per step (mean speed {mean_speed})")

    series = [
        ("reward", frame.history_reward, COLOR_REWARD, 1.8),
        ("speed", frame.history_speed, COLOR_SPEED, 1.4),
        ("accuracy", frame.history_accuracy, COLOR_ACCURACY, 1.4),
        ("occupancy", frame.history_occupancy, COLOR_OCCUPANCY, 1.2),
    ]
    key = []
    n = 0
    low = -0.15
    for label, values, color, lw in series:
        y = np.asarray(values, dtype=float)
        n = max(n, y.size)
        x = np.arange(1, y.size + 1)
        ax.plot(x, y, color=color, linewidth=lw, marker="o" if y.size == 1 else None, markersize=3)
        if y.size and np.isfinite(y).any():
            low = min(low, float(np.nanmin(y)) - 0.05)
        key.append(("\u2501\u2501", color, label))
    if frame.variant == "advanced" and frame.history_mode is not None:
        m = np.asarray(frame.history_mode, dtype=float) / 2.0
        n = max(n, m.size)
        ax.step(np.arange(1, m.size + 1), m, where="mid", color=COLOR_MODE, linewidth=1.2, linestyle="--")
        key.append(("\u254c\u254c", COLOR_MODE, "mode / 2 (0 basic, 0.5 pos., 1 neg.)"))
    ax.axhline(0.0, color="#bbbbbb", linewidth=0.8, zorder=0)
    _step_ticks(ax, _x_limit(frame, n))
    ax.set_ylim(low, 1.1)
    ax.set_yticks([t for t in (-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0) if t >= low])
    ax.grid(True, alpha=0.25)
    _xlabel(ax, "step")
    _key(ax, 0.0, -0.25, key, fontsize=_FS_LEGEND + 0.5)


# --- (7) cumulative reward


def _panel_cumulative(ax, frame: DashboardFrame) -> None:
    from matplotlib.ticker import MaxNLocator

    rewards = np.nan_to_num(np.asarray(frame.history_reward, dtype=float))
    cumulative = np.cumsum(rewards)
    total = float(cumulative[-1]) if cumulative.size else 0.0
    _style(ax, f"Cumulative reward: {total:.2f}")
    x = np.arange(0, cumulative.size + 1)
    y = np.concatenate(([0.0], cumulative))
    ax.plot(x, y, color=COLOR_CUMULATIVE, linewidth=2)
    ax.fill_between(x, y, 0, color=COLOR_CUMULATIVE, alpha=0.15, linewidth=0)
    if cumulative.size:
        ax.plot(x[-1:], y[-1:], "o", color=COLOR_CUMULATIVE, markersize=5, clip_on=False)
    ax.axhline(0.0, color="#bbbbbb", linewidth=0.8, zorder=0)
    _step_ticks(ax, _x_limit(frame, cumulative.size))
    lo, hi = min(0.0, float(y.min())), max(1.0, float(y.max()))
    pad = 0.08 * (hi - lo)
    ax.set_ylim(lo - (pad if lo < 0 else 0.0), hi + pad)
    ax.yaxis.set_major_locator(MaxNLocator(5))
    ax.grid(True, alpha=0.25)
    _xlabel(ax, "step")


# --- (8) KPIs: a figure-level box with two columns of text


def _panel_kpis(fig: Figure, box, frame: DashboardFrame) -> None:
    from matplotlib.patches import FancyBboxPatch

    rewards = np.nan_to_num(np.asarray(frame.history_reward, dtype=float))
    steps = len(frame.history_reward)
    sorted_units = sum(max(0, int(v)) for v in frame.containers)
    rows = [
        ("step", f"{steps} / {int(frame.max_steps)}"),
        ("reward", f"{rewards[-1]:.2f}" if steps else "n/a"),
        ("cumulative reward", f"{rewards.sum():.2f}"),
        ("purity", _pct(frame.purity) if sorted_units else "n/a"),
        ("speed changes", str(count_speed_changes(frame.history_speed))),
        ("speed", f"{_finite(frame.speed):.1f}"),
    ]
    if frame.variant == "advanced":
        rows.append(("mode", _mode_name(frame.mode).split(" ")[0]))

    x0, y0, w, h = _inches(fig, box)
    inch = fig.dpi_scale_trans
    _fig_title(fig, x0 + w / 2, y0 + h, "KPIs")
    fig.add_artist(
        FancyBboxPatch(
            (x0, y0),
            w,
            h,
            boxstyle="round,pad=0,rounding_size=0.08",
            transform=inch,
            facecolor="#f5f5f5",
            edgecolor="#cccccc",
            linewidth=1.0,
        )
    )
    # One text per cell on a shared baseline per row (multi-line texts in two weights drift apart).
    pad = 0.14
    row_h = min(0.3, (h - 2 * pad) / len(rows))
    for i, (name, value) in enumerate(rows):
        y = y0 + h - pad - (i + 0.7) * row_h
        fig.text(x0 + pad, y, name, transform=inch, ha="left", va="baseline", fontsize=_FS_KPI, color="#444444")
        fig.text(x0 + w - pad, y, value, transform=inch, ha="right", va="baseline", fontsize=_FS_KPI, fontweight="bold")

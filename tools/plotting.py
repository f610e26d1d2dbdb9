"""matplotlib for the CLI's plots, without a display, with an error naming the extra to install."""
from __future__ import annotations

from typing import Any


def pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise SystemExit("plots need matplotlib: pip install 'emos[plots]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _check_path(path: str) -> None:
    import os

    if os.path.splitext(path)[1].lower() not in (".png", ".svg", ".pdf"):
        raise SystemExit(f"--plot: the file must end in .png, .svg or .pdf, got {path!r}")


def check_plot_argument(path: str | None) -> None:
    """Fail before a long benchmark, not after it, when ``--plot`` cannot be honoured."""
    if path:
        _check_path(path)
        pyplot()


def save_histograms(path: str, title: str, xlabel: str, series: dict[str, Any]) -> None:
    """One step histogram per named list of values, with its p95 in the legend."""
    import numpy as np

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    values = [np.asarray(v, float) for v in series.values() if len(v)]
    top = max([float(np.percentile(v, 99.5)) for v in values] + [1e-9])
    bins = np.linspace(0, top * 1.05, 60)
    for label, v in series.items():
        if len(v):
            ax.hist(np.asarray(v, float), bins=bins, histtype="step", linewidth=1.8, label=f"{label} (p95 {np.percentile(v, 95):.3g})")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("count")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def save_lines(path: str, title: str, xlabel: str, ylabel: str, series: dict[str, tuple[list[float], list[float]]], log: bool = False) -> None:
    """One line per named (x, y) series."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, (x, y) in series.items():
        ax.plot(x, y, marker="o", linewidth=1.8, label=label)
    if log:
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def draw_map(ax: Any, grid: Any) -> None:
    """An ``OccupancyGridMap`` in world metres: free white, occupied black, unknown grey."""
    import numpy as np

    img = np.where(grid.data < 0, 0.8, 1.0 - grid.data / 100.0)
    h, w = grid.data.shape
    ox, oy, _ = grid.origin
    ax.imshow(img, cmap="gray", origin="lower", vmin=0, vmax=1,
              extent=(ox, ox + w * grid.resolution, oy, oy + h * grid.resolution))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def save_tracks_on_map(path: str, grid: Any, title: str, tracks: dict[str, Any], marks: dict[str, Any] | None = None,
                       label_every: float = 5.0) -> None:
    """Named tracks (world points (N, 2), or (N, 3) with a time in s, labelled every
    ``label_every`` s), drawn from faint to solid as time goes on with an arrow head at the end,
    and marks ((x, y) points) over a map, cropped to the tracks."""
    import numpy as np

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 6))
    draw_map(ax, grid)
    points = [np.asarray(xy, float)[:, :2] for xy in tracks.values() if len(xy)]
    for (label, xyt), colour in zip(tracks.items(), ("tab:blue", "tab:red", "tab:green", "tab:purple")):
        xyt = np.asarray(xyt, float)
        if not len(xyt):
            continue
        xy = xyt[:, :2]
        ax.scatter(xy[:, 0], xy[:, 1], s=6, c=colour, alpha=np.linspace(0.15, 1.0, len(xy)), label=label)
        if len(xy) > 1:
            ax.annotate("", xy=xy[-1], xytext=xy[-2], arrowprops={"arrowstyle": "->", "color": colour})
        if xyt.shape[1] > 2 and label_every > 0:  # a time label where each label_every s step is crossed
            steps = np.floor(xyt[:, 2] / label_every)
            for k in np.flatnonzero(np.diff(steps) != 0) + 1:
                ax.annotate(f"{xyt[k, 2]:+.0f} s", tuple(xy[k]), fontsize=7, color=colour, textcoords="offset points", xytext=(3, -8))
    for label, (x, y) in (marks or {}).items():
        ax.plot([x], [y], "kx", markersize=10)
        ax.annotate(label, (x, y), textcoords="offset points", xytext=(6, 6))
    if points:
        allp = np.concatenate(points)
        lo, hi = allp.min(axis=0) - 1.0, allp.max(axis=0) + 1.0
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
    ax.set_title(title)
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)

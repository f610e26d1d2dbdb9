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

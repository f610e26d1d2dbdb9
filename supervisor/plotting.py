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

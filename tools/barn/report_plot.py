"""``emos bench barn --report FILE --plot PICTURE``: every trial of a results file in one picture.

One cell per trial, worlds left to right (50 to a row), a world's seeds top to bottom, coloured
by outcome: where the failures sit (one world's seeds, one stretch of worlds, the report split)
shows at a glance in a run of 2500 trials. With ``--against OTHER`` both files are drawn one
above the other on the world-seed pairs both hold, so a cell that changes colour is a trial
that changed outcome between the two versions.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .harness import EpisodeResult

WORLDS_PER_ROW = 50
# Outcome codes of a cell, and their colours (RGB, 0-1).
NOT_RUN, SUCCESS, SLOW_SUCCESS, TIMEOUT, COLLISION = range(5)
COLOURS = np.array([
    (0.93, 0.93, 0.93),  # not run (yet)
    (0.16, 0.62, 0.28),  # success within 2 OT: the full metric
    (0.70, 0.85, 0.35),  # success slower than 2 OT: a lower metric
    (0.98, 0.60, 0.10),  # time limit
    (0.85, 0.12, 0.12),  # collision
])
LABELS = ["not run", "success (full metric)", "success (slower than 2 OT)", "time limit", "collision"]
FULL_METRIC = 0.5  # OT / 2 OT: every success at least twice as fast as the optimal time scores this


def outcome(t: EpisodeResult) -> int:
    """The cell code of one trial."""
    if t.success:
        return SUCCESS if t.metric >= FULL_METRIC - 1e-3 else SLOW_SUCCESS
    return COLLISION if t.collided else TIMEOUT


def outcome_grid(trials: Sequence[EpisodeResult], worlds: Sequence[int] | None = None) -> tuple[list[int], np.ndarray]:
    """``(worlds, grid)``: the worlds as columns (sorted; ``worlds`` to fix them) and an
    (seeds, worlds) array of outcome codes, a world's trials in the order of their seeds."""
    by_world: dict[int, list[EpisodeResult]] = {}
    for t in trials:
        by_world.setdefault(t.idx, []).append(t)
    columns = sorted(by_world) if worlds is None else list(worlds)
    rows = max((len(v) for v in by_world.values()), default=0)
    grid = np.full((max(rows, 1), len(columns)), NOT_RUN, dtype=np.int8)
    for col, idx in enumerate(columns):
        for row, t in enumerate(sorted(by_world.get(idx, []), key=lambda t: t.seed)):
            grid[row, col] = outcome(t)
    return columns, grid


def save_outcome_map(path: str | Path, panels: Sequence[tuple[str, Sequence[EpisodeResult]]]) -> None:
    """Draw each ``(title, trials)`` panel's outcome grid, one above the other, into ``path``
    (.png, .svg or .pdf). The panels share their columns: every world any panel holds."""
    from emos.tools.plotting import pyplot

    plt = pyplot()
    worlds = sorted({t.idx for _, trials in panels for t in trials})
    grids = [outcome_grid(trials, worlds)[1] for _, trials in panels]
    bands = max(1, -(-len(worlds) // WORLDS_PER_ROW))
    seeds = max(g.shape[0] for g in grids)
    heights = [seeds] * (bands * len(panels))
    fig, axes = plt.subplots(len(heights), 1, squeeze=False, gridspec_kw={"height_ratios": heights},
                             figsize=(12, 0.9 + 0.12 * seeds * len(heights) + 0.35 * len(heights)))
    for p, ((title, trials), grid) in enumerate(zip(panels, grids)):
        for band in range(bands):
            ax = axes[p * bands + band, 0]
            cols = slice(band * WORLDS_PER_ROW, (band + 1) * WORLDS_PER_ROW)
            shown = np.full((seeds, WORLDS_PER_ROW), NOT_RUN, dtype=np.int8)
            part = grid[:, cols]
            shown[: part.shape[0], : part.shape[1]] = part
            ax.imshow(COLOURS[shown], aspect="auto", interpolation="nearest")
            band_worlds = worlds[cols]
            # Ticks on the report split's worlds (idx % 5 == 0), which are never tuned on.
            ticks = [i for i, idx in enumerate(band_worlds) if idx % 5 == 0]
            ax.set_xticks(ticks, [str(band_worlds[i]) for i in ticks], fontsize=7)
            ax.set_yticks([])
            ax.set_xlim(-0.5, WORLDS_PER_ROW - 0.5)
            if band == 0:
                ax.set_title(f"{title}: {_summary(trials)}", fontsize=9, loc="left")
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLOURS[code]) for code in range(len(LABELS))]
    fig.legend(handles, LABELS, loc="lower center", bbox_to_anchor=(0.5, 0.012), ncol=len(LABELS), fontsize=8, frameon=False)
    fig.text(0.5, 0.004, "columns: worlds, in order (ticks on the report split, idx % 5 == 0); rows: a world's seeds",
             fontsize=7, color="0.35", ha="center")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _summary(trials: Sequence[EpisodeResult]) -> str:
    n = len(trials)
    if not n:
        return "no finished trial"
    collisions = sum(t.collided for t in trials)
    return (f"{n} trials, success {sum(t.success for t in trials) / n:.3f}, collision {collisions / n:.3f}, "
            f"metric {sum(t.metric for t in trials) / n:.4f}")

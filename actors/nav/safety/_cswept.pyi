"""Types of the swept check's C inner loop (actors/nav/safety/_cswept.c, built when a C compiler
is present): ``touches`` returns what ``SweptFootprint._touches`` returns (swept.py)."""
import numpy as np

def touches(
    poses: np.ndarray,
    homog: np.ndarray,
    norm2: np.ndarray,
    start: np.ndarray,
    limits: np.ndarray,
    steps: np.ndarray,
    shared: int,
    shared_limit: float,
    decisive: int,
    shape: tuple[int, float, float, float, float, int, int, float],
    /,
) -> list[tuple[bool, float, bool, bool] | None]: ...

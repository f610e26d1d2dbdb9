"""The nemesis catalogue: ``kind`` name -> class (what scenario files name)."""
from __future__ import annotations

from emos.chaos.nemesis.base import Compose, Nemesis, NemesisError
from emos.chaos.nemesis.method import MethodFault
from emos.chaos.nemesis.process import (
    HangComponent,
    KillComponent,
    KillGroup,
    KillMonitor,
    KillZygote,
    StarveComponent,
    TermDeafComponent,
)
from emos.chaos.nemesis.proxy import FaultProxy, ProxyFault
from emos.chaos.nemesis.sensor import SensorFault
from emos.chaos.nemesis.shm import DeleteSegment, ScribbleSegment

CATALOGUE: dict[str, type[Nemesis]] = {
    cls.kind: cls
    for cls in (KillComponent, HangComponent, StarveComponent, KillZygote, KillGroup, ProxyFault, ScribbleSegment, DeleteSegment, SensorFault,
                TermDeafComponent, KillMonitor, MethodFault)
}


def make(spec: dict, where: str = "nemesis") -> Nemesis:
    """Build a nemesis from a scenario entry ``{kind: kill, target: random, ...}``."""
    if not isinstance(spec, dict) or "kind" not in spec:
        raise NemesisError(f"{where}: expected a mapping with 'kind' (one of {', '.join(sorted(CATALOGUE))}), got {spec!r}")
    params = {k: v for k, v in spec.items() if k not in ("kind", "duration", "weight")}
    kind = spec["kind"]
    if kind == "compose":
        parts = params.pop("parts", None)
        if not isinstance(parts, list):
            raise NemesisError(f"{where}: compose needs 'parts', a list of nemeses")
        return Compose([make(p, f"{where}.parts[{i}]") for i, p in enumerate(parts)])
    cls = CATALOGUE.get(kind)
    if cls is None:
        import difflib

        close = difflib.get_close_matches(str(kind), CATALOGUE, n=2)
        hint = f"; did you mean {' or '.join(close)}?" if close else ""
        raise NemesisError(f"{where}: unknown nemesis kind {kind!r}{hint} (known: {', '.join(sorted(CATALOGUE))})")
    try:
        return cls(**params)
    except TypeError as exc:
        raise NemesisError(f"{where}: bad parameters for {kind}: {exc}") from None


__all__ = ["CATALOGUE", "Compose", "FaultProxy", "Nemesis", "NemesisError", "make"]

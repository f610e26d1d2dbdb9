"""``MemoryStore``: a bounded spatio-temporal index of what the robot saw and did.

Every record has a time, a place (map x, y; unknown places are NaN), a kind (``detection``,
``caption``, ``event``, ``state``, ``episode``) and a text; detections keep their labels. The
index answers by place (within a radius), by time (seconds ago), by label (``locate``: where an
object was last seen) and by meaning (through a vector store such as :class:`ChromaClient`,
handed in; without one, by shared words). The robot's own state (pose, battery, faults) is
kept apart as its latest value (``body_status``) and recorded when it changes.

Storage is bounded: past ``max_records``, the oldest quarter of the records (earlier episodes too)
is consolidated into episodes (one record per ``episode_s`` window or longer, its text a summary made by the
``summarize`` callable, e.g. the language model; by default a count of what was seen), and the
raw records and their vectors are removed. ``locate`` keeps the last sighting of each label
(at most ``max_labels``) beyond consolidation.

Queries with impossible ranges (a negative radius, a time in the future, a window that ends
before it starts, NaN) raise :class:`MemoryQueryError` naming the argument and the reason.
"""
from __future__ import annotations

import math
import threading
import time
import uuid
from collections import Counter, OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

import attrs
import numpy as np

from emos.errors import EmosError

__all__ = ["MemoryStore", "MemoryRecord", "MemoryQueryError", "KINDS"]

KINDS = ("detection", "caption", "event", "state", "episode")
COLLECTION = "emos_memory"


class MemoryQueryError(EmosError, ValueError):
    """A memory query that cannot be answered as asked (an impossible range); says why."""


@attrs.frozen
class MemoryRecord:
    id: str
    t: float
    x: float
    y: float
    kind: str
    text: str
    labels: tuple[str, ...] = ()
    t_end: float | None = None  # episodes: the end of the window they summarize

    def asdict(self, now: float) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "text": self.text, "ago_s": round(now - self.t, 1),
                               "time": time.strftime("%H:%M:%S", time.localtime(self.t))}
        if math.isfinite(self.x) and math.isfinite(self.y):
            out["x"], out["y"] = round(self.x, 2), round(self.y, 2)
        if self.labels:
            out["labels"] = list(self.labels)
        return out


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MemoryQueryError(f"{name} must be a number, got {type(value).__name__} {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise MemoryQueryError(f"{name} must be a finite number, got {value!r}")
    return value


def _query_count(name: str, value: Any, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= hi:
        raise MemoryQueryError(f"{name} must be an integer in [1, {hi}], got {value!r}")
    return value


def _text(name: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise MemoryQueryError(f"{name} must be a non-empty text, got {value!r}")
    return value.strip()


def default_summary(records: Sequence[MemoryRecord]) -> str:
    """A summary without a model: what was seen how often, and the events, in order."""
    seen = Counter(label for r in records for label in r.labels)
    parts = []
    if seen:
        parts.append("saw " + ", ".join(f"{label} x{n}" for label, n in seen.most_common(8)))
    events = [r.text for r in records if r.kind in ("event", "caption", "state", "episode")]
    if events:
        parts.append("; ".join(dict.fromkeys(events))[:400])
    return ". ".join(parts) or f"{len(records)} observations"


class MemoryStore:
    """See the module doc. Thread-safe: a component's worker writes while its loop queries."""

    def __init__(self, *, max_records: int = 5000, episode_s: float = 60.0, max_labels: int = 1000,
                 vector: Any = None, collection: str = COLLECTION, clock: Callable[[], float] = time.time,
                 summarize: Callable[[Sequence[MemoryRecord]], str] | None = None) -> None:
        if isinstance(max_records, bool) or not isinstance(max_records, int) or max_records < 8:
            raise ValueError(f"MemoryStore: max_records must be an int >= 8, got {max_records!r}")
        if not (isinstance(episode_s, (int, float)) and math.isfinite(episode_s) and episode_s > 0):
            raise ValueError(f"MemoryStore: episode_s must be a number of seconds > 0, got {episode_s!r}")
        self.max_records, self.episode_s, self.max_labels = max_records, float(episode_s), max_labels
        self.vector, self.collection, self.clock = vector, collection, clock
        self.summarize = summarize or default_summary
        self._records: list[MemoryRecord] = []
        self._last_seen: OrderedDict[str, MemoryRecord] = OrderedDict()
        self.body: dict[str, Any] = {"x": math.nan, "y": math.nan, "battery": None, "faults": {}}
        self.consolidations = 0
        self._lock = threading.RLock()

    # ------------------------------------------------------------------ writing
    def __len__(self) -> int:
        return len(self._records)

    def add(self, kind: str, text: str, *, x: float | None = None, y: float | None = None, t: float | None = None,
            labels: Sequence[str] = ()) -> MemoryRecord:
        """Remember one thing; the place defaults to the robot's current one."""
        if kind not in KINDS:
            raise ValueError(f"MemoryStore.add: kind must be one of {KINDS}, got {kind!r}")
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"MemoryStore.add: text must be a non-empty str, got {text!r}")
        with self._lock:
            rec = MemoryRecord(id=uuid.uuid4().hex, t=self.clock() if t is None else float(t),
                               x=self.body["x"] if x is None else float(x), y=self.body["y"] if y is None else float(y),
                               kind=kind, text=text.strip()[:1000], labels=tuple(str(v) for v in labels))
            self._records.append(rec)
            for label in rec.labels:
                self._last_seen[label] = rec
                self._last_seen.move_to_end(label)
            while len(self._last_seen) > self.max_labels:
                self._last_seen.popitem(last=False)
            self._index([rec])
            if len(self._records) > self.max_records:
                self.consolidate()
        return rec

    def observe_detections(self, labels: Sequence[str], x: float | None = None, y: float | None = None) -> MemoryRecord | None:
        labels = [str(v) for v in labels if str(v)]
        if not labels:
            return None
        counts = Counter(labels)
        text = "saw " + ", ".join(f"{n} {label}" if n > 1 else label for label, n in sorted(counts.items()))
        return self.add("detection", text, x=x, y=y, labels=sorted(counts))

    def update_body(self, *, x: float | None = None, y: float | None = None, battery: float | None = None,
                    faults: dict[str, str] | None = None) -> None:
        """The robot's latest state; a change of battery decile or of faults is also recorded."""
        with self._lock:
            if x is not None and y is not None:
                self.body["x"], self.body["y"] = float(x), float(y)
            if battery is not None:
                old = self.body["battery"]
                self.body["battery"] = float(battery)
                if old is None or int(old * 10) != int(float(battery) * 10):
                    self.add("state", f"battery at {round(float(battery) * 100)}%")
            if faults is not None:
                old_faults = self.body["faults"]
                self.body["faults"] = dict(faults)
                for name, what in faults.items():
                    if old_faults.get(name) != what:
                        self.add("state", f"{name}: {what}")
                for name in set(old_faults) - set(faults):
                    self.add("state", f"{name}: recovered")

    def _index(self, records: Sequence[MemoryRecord]) -> None:
        if self.vector is None or not records:
            return
        self.vector.add(self.collection, [r.text for r in records], metadatas=[{"t": r.t, "kind": r.kind} for r in records],
                        ids=[r.id for r in records])

    # ------------------------------------------------------------------ consolidation
    def consolidate(self) -> int:
        """Fold the oldest quarter of the records into episodes (at least 4:1); returns how many were folded."""
        with self._lock:
            # The oldest quarter, earlier episodes included: episodes fold into longer ones, so the
            # total stays bounded however long the robot runs.
            old = sorted(self._records, key=lambda r: r.t)[: max(2, len(self._records) // 4)]
            if len(old) < 2:
                return 0
            window = self.episode_s
            while True:
                groups: dict[int, list[MemoryRecord]] = {}
                for r in old:
                    groups.setdefault(int(r.t // window), []).append(r)
                if len(groups) <= max(1, len(old) // 4):
                    break
                window *= 2  # too little folds in one window: widen it until it shrinks 4:1
            gone = {r.id for r in old}
            episodes = []
            for _, group in sorted(groups.items()):
                xs = np.array([r.x for r in group], dtype=float)
                ys = np.array([r.y for r in group], dtype=float)
                finite = np.isfinite(xs) & np.isfinite(ys)
                cx = float(xs[finite].mean()) if finite.any() else math.nan
                cy = float(ys[finite].mean()) if finite.any() else math.nan
                try:
                    summary = self.summarize(group)
                except Exception as exc:  # a model that fails must not lose the memories' gist
                    summary = f"{default_summary(group)} (summary by the model failed: {type(exc).__name__})"
                labels = tuple(sorted({label for r in group for label in r.labels}))
                episodes.append(MemoryRecord(id=uuid.uuid4().hex, t=group[0].t, x=cx, y=cy, kind="episode",
                                             text=summary[:1000] or "(empty episode)", labels=labels, t_end=group[-1].t))
            self._records = sorted([r for r in self._records if r.id not in gone] + episodes, key=lambda r: r.t)
            if self.vector is not None:
                self.vector.delete(self.collection, ids=sorted(gone))
            self._index(episodes)
            self.consolidations += 1
            return len(old)

    # ------------------------------------------------------------------ queries
    def _arrays(self) -> tuple[list[MemoryRecord], np.ndarray, np.ndarray, np.ndarray]:
        recs = list(self._records)
        return recs, np.array([r.t for r in recs]), np.array([r.x for r in recs]), np.array([r.y for r in recs])

    def spatial_query(self, x: float, y: float, radius: float, n_results: int = 20) -> list[dict[str, Any]]:
        x, y, radius = _number("x", x), _number("y", y), _number("radius", radius)
        if radius < 0:
            raise MemoryQueryError(f"radius must be >= 0 m, got {radius:g}: a negative radius holds nothing")
        n_results = _query_count("n_results", n_results, 200)
        with self._lock:
            recs, ts, xs, ys = self._arrays()
        if not recs:
            return []
        with np.errstate(invalid="ignore"):
            d = np.hypot(xs - x, ys - y)
            hit = np.flatnonzero(d <= radius)
        hit = hit[np.argsort(-ts[hit])][:n_results]  # newest first
        now = self.clock()
        return [dict(recs[i].asdict(now), distance_m=round(float(d[i]), 2)) for i in hit]

    def temporal_query(self, since_s: float, until_s: float = 0.0, n_results: int = 50) -> list[dict[str, Any]]:
        since_s, until_s = _number("since_s", since_s), _number("until_s", until_s)
        for name, value in (("since_s", since_s), ("until_s", until_s)):
            if value < 0:
                raise MemoryQueryError(f"{name}={value:g} is in the future: times are seconds ago, >= 0")
        if until_s > since_s:
            raise MemoryQueryError(f"until_s={until_s:g} is before since_s={since_s:g}: the window would end before it starts")
        n_results = _query_count("n_results", n_results, 200)
        now = self.clock()
        with self._lock:
            recs, ts, _, _ = self._arrays()
        if not recs:
            return []
        hit = np.flatnonzero((ts >= now - since_s) & (ts <= now - until_s))
        return [recs[i].asdict(now) for i in hit[-n_results:]]

    def episode_summary(self, since_s: float, summarize: Callable[[Sequence[MemoryRecord]], str] | None = None) -> str:
        since_s = _number("since_s", since_s)
        if since_s < 0:
            raise MemoryQueryError(f"since_s={since_s:g} is in the future: times are seconds ago, >= 0")
        now = self.clock()
        with self._lock:
            recs = [r for r in self._records if r.t >= now - since_s or (r.t_end or r.t) >= now - since_s]
        if not recs:
            return f"nothing remembered in the last {since_s:g} s"
        return (summarize or self.summarize)(recs)

    def locate(self, label: str) -> dict[str, Any]:
        label = _text("label", label)
        with self._lock:
            rec = self._last_seen.get(label) or next((r for lbl, r in reversed(self._last_seen.items()) if lbl.lower() == label.lower()), None)
        if rec is None:
            return {"label": label, "found": False, "text": f"never saw a {label}"}
        return dict(rec.asdict(self.clock()), label=label, found=True)

    def semantic_search(self, query: str, n_results: int = 3) -> list[dict[str, Any]]:
        query = _text("query", query)
        n_results = _query_count("n_results", n_results, 50)
        now = self.clock()
        with self._lock:
            by_id = {r.id: r for r in self._records}
        if self.vector is not None:
            hits = self.vector.query(self.collection, query, n_results=n_results)
            return [dict(by_id[h.id].asdict(now), distance=round(float(h.distance), 3)) for h in hits if h.id in by_id]
        words = set(query.lower().split())
        scored = sorted(by_id.values(), key=lambda r: (-len(words & set(r.text.lower().split())), -r.t))
        return [r.asdict(now) for r in scored[:n_results] if words & set(r.text.lower().split())]

    def recall(self, subject: str) -> dict[str, Any]:
        subject = _text("subject", subject)
        out: dict[str, Any] = {"subject": subject, "memories": self.semantic_search(subject, 5)}
        seen = self.locate(subject.split()[-1])
        if seen.get("found"):
            out["last_seen"] = seen
        return out

    def body_status(self) -> dict[str, Any]:
        with self._lock:
            body = dict(self.body)
        out: dict[str, Any] = {"faults": body["faults"] or "none"}
        if math.isfinite(body["x"]) and math.isfinite(body["y"]):
            out["x"], out["y"] = round(body["x"], 2), round(body["y"], 2)
        out["battery"] = "unknown" if body["battery"] is None else f"{round(body['battery'] * 100)}%"
        return out

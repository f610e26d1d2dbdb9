"""Shared-memory faults: scribble over a topic's ring, or delete it.

These are what a crashed writer, a stray process or a hostile neighbour can do to ``/dev/shm``.
The runtime must never deliver a corrupt message, and the topic must flow again once the writer
has been restarted (``then_kill``) or has moved to a fresh generation.
"""
from __future__ import annotations

import os
import signal
from typing import Any

from emos.chaos.history import Record
from emos.chaos.nemesis.base import Nemesis, NemesisError
from emos.transport.context import SHM_DIR, encode_name


class _SegmentFault(Nemesis):
    expects = "topic"

    def __init__(self, topic: str, then_kill: str | None = None, **params: Any) -> None:
        super().__init__(topic=topic, **({"then_kill": then_kill} if then_kill else {}), **params)
        if not isinstance(topic, str) or not topic:
            raise NemesisError(f"{self.kind}: topic must be a topic name, got {topic!r}")
        self.topic = topic if topic.startswith("/") else "/" + topic
        self.then_kill = then_kill

    def _segments(self) -> list[str]:
        assert self.system is not None and self.system.run_id is not None
        prefix = f"emos.{self.system.run_id}.{encode_name(self.topic)}."
        return sorted(n for n in os.listdir(SHM_DIR) if n.startswith(prefix))

    def _kill_writer(self) -> dict[str, Any]:
        if not self.then_kill:
            return {}
        assert self.system is not None
        pid = self.system.pid_of(self.then_kill)
        if pid is None:
            raise NemesisError(f"{self.kind}: no running component {self.then_kill!r} to kill")
        os.kill(pid, signal.SIGKILL)
        return {"killed": self.then_kill, "pid": pid}

    def start(self) -> Record | None:
        segments = self._segments()
        if not segments:
            return None
        name = segments[-1]  # the newest generation is the live one
        self.damage(SHM_DIR / name)
        extra = self._kill_writer()
        record = self._fault(target=self.topic, segment=name, **extra)
        self.active = None
        return record

    def damage(self, path: os.PathLike[str]) -> None:
        raise NotImplementedError


class ScribbleSegment(_SegmentFault):
    kind = "shm_scribble"
    summary = "overwrite a topic ring's header and message map with garbage (optionally kill its writer)"

    def __init__(self, topic: str, length: int = 4096, **params: Any) -> None:
        super().__init__(topic, length=length, **params)
        self.length = int(length)

    def damage(self, path: os.PathLike[str]) -> None:
        fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW)
        try:
            size = os.fstat(fd).st_size
            os.pwrite(fd, bytes(self.rng.getrandbits(8) for _ in range(min(self.length, size))), 0)
        finally:
            os.close(fd)


class DeleteSegment(_SegmentFault):
    kind = "shm_delete"
    summary = "unlink a topic's ring from /dev/shm (optionally kill its writer)"

    def damage(self, path: os.PathLike[str]) -> None:
        os.unlink(path)

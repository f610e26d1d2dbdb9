"""A publisher's ring generations in ``/dev/shm``: finding its newest own one, creating the next.

Names in the run's namespace may have been planted by another user (see ``trust.py``): the
newest generation counts only if it is a regular file of ours, and creating a generation whose
name is taken moves on to the next number instead of failing or adopting the file.
"""
from __future__ import annotations

import os

from emos.transport import ring as R
from emos.transport.context import SHM_DIR, RunContext, encode_name
from emos.transport.trust import check_path, rate_limited

# How many generation numbers a publisher skips past names other users planted before giving up.
MAX_GENERATION_SKIPS = 64


def latest_own_generation(ctx: RunContext, topic: str, publisher_id: str) -> int | None:
    """The newest generation of ``publisher_id``'s ring on ``topic`` that is ours, or ``None``."""
    prefix = f"{ctx.shm_prefix}{encode_name(topic)}.{encode_name(publisher_id)}.g"
    best = None
    for n in os.listdir(SHM_DIR):
        if n.startswith(prefix) and n[len(prefix) :].isdigit():
            reason = check_path(SHM_DIR / n)
            if reason is None:
                best = max(best or 0, int(n[len(prefix) :]))
            elif reason != "vanished":
                rate_limited.warning(f"distrust:{n}", "topic %s: ignoring segment %s: %s", topic, n, reason)
    return best


def create_generation(
    ctx: RunContext, topic: str, publisher_id: str, generation: int, depth: int, capacity: int, fingerprint: str, type_name: str, first: int
) -> R.Ring:
    """A new ring for ``publisher_id`` at ``generation`` or, if that name is taken, the next free one."""
    for gen in range(generation, generation + MAX_GENERATION_SKIPS):
        name = ctx.segment_name(topic, publisher_id, gen)
        try:
            return R.Ring.create(name, depth, capacity, fingerprint, type_name, generation=gen, first=first)
        except FileExistsError:
            # Not a ring of ours (the publisher looked for those): someone planted the name.
            rate_limited.warning(f"taken:{name}", "topic %s: segment name %s is taken (%s); trying the next generation", topic, name, check_path(SHM_DIR / name))
    raise R.RingError(
        f"topic {topic!r}: publisher {publisher_id!r} found generations {generation}..{gen} of its ring "
        f"all taken by files that are not its own in {SHM_DIR}; remove them"
    )

"""Zero-copy messages: a subscriber's loans on one ring, and a publisher's loaned message.

A loan hands the subscriber a read-only numpy view of a message in the publisher's ring instead
of a copy, and pins that slot so the writer writes elsewhere meanwhile (see ``ring.py``). The
loan lasts exactly as long as the view: decoded arrays are views of it and keep it alive, and
when the last of them is garbage collected a weak-reference callback unpins the slot. Keeping a
message (in a list, as a component's latest input) keeps its loan; a subscriber that has used
up its pin entries receives copies until one is returned, so holding on to messages never stalls
the publisher nor blocks delivery.

A publisher's loan (:class:`PublisherLoan`, from ``Publisher.loan``) is the other direction: the
message's array is a writable view of the next ring slot, so a camera driver or the simulator
fills its frame straight into shared memory and the commit writes only the metadata in front of
it. The slot is claimed as any write claims it (``seq`` odd): readers never see it until the
commit, a loan ended by an exception is abandoned (``Ring.abandon``), and a writer killed while
the loan is open leaves exactly what a writer killed mid-copy leaves. The frame is the codec's
usual one, with the loaned array at byte ``LOAN_META_BYTES`` and the metadata before it pointing
there (array offsets in a frame are free), so subscribers decode it like any other message.
"""
from __future__ import annotations

import math
import time
import weakref
from functools import partial
from typing import TYPE_CHECKING, Any

import msgpack
import numpy as np

from emos.msgs import codec
from emos.transport import ring as R

if TYPE_CHECKING:
    from emos.transport.pubsub import Publisher

_ring_loan = None if R.RING_C is None else R.RING_C.ring_loan
LOANS_PER_SUBSCRIBER = 2
# Below this a copy is cheaper than a loan's bookkeeping (a fence, a weak reference: ~2 us).
LOAN_MIN_BYTES = 16 * 1024
# Room for a loaned message's metadata (its frame header) before its array: the array sits at
# this offset of the slot whatever the other fields hold; metadata past it is refused.
LOAN_META_BYTES = 4096


class LoanBook:
    """The pin entries one subscriber claimed on one ring, and the loans outstanding on them."""

    def __init__(self, ring: R.Ring, wanted: int = LOANS_PER_SUBSCRIBER):
        self.ring = ring
        self.table = ring.pins()
        self.entries = self.table.claim(ring.fd, wanted) if wanted > 0 else []
        self.free = list(self.entries)
        self._refs: dict[int, weakref.ref[np.ndarray]] = {}  # pin entry -> the array lent on it
        self.closed = False

    @property
    def outstanding(self) -> int:
        return len(self._refs)

    def loan(self, n: int) -> tuple[int, np.ndarray | None, int] | None:
        """Message ``n`` as a pinned view, or ``None`` when every entry is lent (copy instead)."""
        if not self.free:
            return None
        entry = self.free.pop()
        ring = self.ring
        got = None if _ring_loan is None else _ring_loan(ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity, n, entry)
        # One C call (ring.py's module doc); anything it does not take, Ring.loan reads again and
        # reports (a slot outside the ring, a length past it: RingCorrupt).
        status, view, stamp = got if got is not None else ring.loan(n, entry)
        if status != R.OK or view is None:
            self.free.append(entry)
            return status, None, 0
        self._refs[entry] = weakref.ref(view, partial(self._returned, entry))
        return R.OK, view, stamp

    def _returned(self, entry: int, _ref: object) -> None:
        # Runs in whichever thread dropped the last reference, possibly after close().
        self.table.release(entry)
        self._refs.pop(entry, None)
        if self.closed:
            self.table.abandon(entry)
            if not self._refs:
                self.table.close()
        else:
            self.free.append(entry)

    def close(self) -> None:
        """Give back idle entries now; entries still lent are given back when their loan ends."""
        if self.closed:
            return
        self.closed = True
        idle = [e for e in self.entries if e not in self._refs]
        if self.ring.mm is not None:
            self.table.unclaim(self.ring.fd, idle)
        self.free.clear()
        if not self._refs:
            self.table.close()


def _align8(n: int) -> int:
    return (n + 7) & ~7


def _message_around(msg_cls: type, arr: np.ndarray, field: str, fields: dict[str, Any]) -> Any:
    """A ``msg_cls`` holding ``arr`` as ``field`` and ``fields`` as the rest. Image and friends
    (``from_numpy``) derive height, width, step and encoding from the array."""
    fields = dict(fields)
    if field == "data" and hasattr(msg_cls, "from_numpy") and "data" not in fields:
        kwargs = {k: fields.pop(k) for k in ("encoding", "header") if k in fields}
        msg = msg_cls.from_numpy(arr, **kwargs)
        for name, value in fields.items():
            setattr(msg, name, value)
        return msg
    msg = msg_cls(**fields)
    setattr(msg, field, arr)
    return msg


class _PlacedArrays:
    """The codec's array collector for a loaned frame: the loaned array is already at
    ``position``; any other array goes after it, to be copied there. Offsets are relative to
    the array region, which starts at ``base`` (the codec's frame layout)."""

    def __init__(self, loaned: np.ndarray, position: int, base: int):
        self.loaned_at = loaned.__array_interface__["data"][0]
        self.loaned_bytes = loaned.nbytes
        self.position = position
        self.base = base
        self.end = position + _align8(loaned.nbytes)
        self.extras: list[tuple[int, np.ndarray]] = []  # (frame offset, array to copy there)

    def __call__(self, arr: np.ndarray) -> msgpack.ExtType:
        if arr.dtype.hasobject or arr.dtype.fields is not None:
            raise TypeError(f"cannot encode an array of dtype {arr.dtype}: only plain numeric dtypes travel on topics")
        if arr.__array_interface__["data"][0] == self.loaned_at and arr.nbytes == self.loaned_bytes and arr.flags.c_contiguous:
            at = self.position  # in place: nothing to copy
        else:
            arr = np.ascontiguousarray(arr)
            at = self.end
            self.extras.append((at, arr))
            self.end = at + _align8(arr.nbytes)
        return msgpack.ExtType(1, msgpack.packb((arr.dtype.str, arr.shape, at - self.base)))


class PublisherLoan:
    """``with pub.loan(Image, shape=(480, 640, 3)) as msg:`` fill ``msg.data`` (or
    ``msg.to_numpy()``), set the other fields; the message is published when the block ends
    and abandoned if it raises (module doc). ``msg`` and its arrays are valid only inside the
    block: the slot belongs to the ring again after it."""

    def __init__(self, pub: Publisher, msg_cls: type, shape: tuple[int, ...], dtype: Any, field: str, fields: dict[str, Any]):
        if msg_cls is not pub.msg_cls:
            from emos.transport.pubsub import TopicTypeError

            raise TopicTypeError(f"topic {pub.topic!r} carries {pub.type_name}, cannot loan a {getattr(msg_cls, '__name__', msg_cls)}")
        self.pub = pub
        self.msg_cls = msg_cls
        self.shape = tuple(int(d) for d in shape)
        if any(d < 0 for d in self.shape):
            raise ValueError(f"topic {pub.topic!r}: a loaned array needs a shape of sizes >= 0, got {shape}")
        self.dtype = np.dtype(dtype)
        if self.dtype.hasobject or self.dtype.fields is not None:
            raise TypeError(f"topic {pub.topic!r}: cannot loan an array of dtype {self.dtype}: only plain numeric dtypes travel on topics")
        self.field = field
        self.fields = fields
        self.msg: Any = None
        self._n = -1
        self._ring: R.Ring | None = None
        self._array: np.ndarray | None = None
        self._started = 0

    def __enter__(self) -> Any:
        pub = self.pub
        nbytes = math.prod(self.shape) * self.dtype.itemsize
        ring = pub._begin_loan(LOAN_META_BYTES + _align8(nbytes))
        n, buf = ring.begin(ring.capacity, pub.reuse_recent)  # the whole slot: arrays other than the loaned one go after it
        buf.release()  # the array below maps the segment itself, as a reader's loan does
        self._n, self._ring = n, ring
        try:
            arr = np.ndarray(self.shape, self.dtype, ring.mm, ring.pending_offset() + LOAN_META_BYTES)
            self._array = arr
            self.msg = self._build(arr)
            self._started = pub._announce_write(ring, nbytes)
        except BaseException:
            self._abandon()
            raise
        return self.msg

    def _build(self, arr: np.ndarray) -> Any:
        """The message with ``arr`` as its ``field``, the way the message class would hold it."""
        msg = _message_around(self.msg_cls, arr, self.field, self.fields)
        held = getattr(msg, self.field, None)
        if not isinstance(held, np.ndarray) or held.__array_interface__["data"][0] != arr.__array_interface__["data"][0]:
            raise TypeError(f"topic {self.pub.topic!r}: {self.msg_cls.__name__}.{self.field} does not hold a {self.dtype} array "
                            f"of shape {self.shape} as it is (its field converts it): loan it with the field's own dtype")
        return msg

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is not None:
            self._abandon()
            return
        try:
            self._commit()
        except BaseException:
            self._abandon()
            raise

    def _commit(self) -> None:
        ring, arr, pub = self._ring, self._array, self.pub
        assert ring is not None and arr is not None
        payload = ring.pending_offset()
        encoder = codec._ENCODERS.get(self.msg_cls) or codec._compile_encoder(self.msg_cls)
        base = _align8(4)
        for _ in range(4):  # array offsets are relative to the end of the metadata: settle both
            placed = _PlacedArrays(arr, LOAN_META_BYTES, base)
            meta = codec._packer().pack(encoder(self.msg, placed))
            settled = _align8(4 + len(meta))
            if settled == base:
                break
            base = settled
        else:
            raise RuntimeError(f"topic {pub.topic!r}: the metadata of a loaned {pub.type_name} did not settle")
        if base > LOAN_META_BYTES:
            raise R.MessageTooLarge(f"topic {pub.topic!r}: a loaned {pub.type_name}'s fields take {len(meta)} B, "
                                    f"more than the {LOAN_META_BYTES - 4} B a loan leaves before its array")
        if placed.end > ring.capacity:
            raise R.MessageTooLarge(f"topic {pub.topic!r}: a loaned {pub.type_name} of {placed.end} B does not fit its slot "
                                    f"of {ring.capacity} B (its other arrays grew it)")
        mm = ring.mm
        mm[payload : payload + 4] = len(meta).to_bytes(4, "little")
        mm[payload + 4 : payload + 4 + len(meta)] = meta
        if placed.extras:
            dst = np.frombuffer(mm, np.uint8, count=placed.end, offset=payload)
            for at, extra in placed.extras:
                dst[at : at + extra.nbytes] = extra.reshape(-1).view(np.uint8)
            del dst
        self._seal()  # the slot is the readers' now
        stamp = time.time_ns()
        pub._end_loan()
        pub._finish(ring, self._n, placed.end, stamp, self._started)
        self._ring = self._array = None

    def _seal(self) -> None:
        """Make the lent arrays read-only: after the block the slot is not the caller's."""
        for arr in (self._array, getattr(self.msg, self.field, None)):
            if isinstance(arr, np.ndarray):
                arr.flags.writeable = False

    def _abandon(self) -> None:
        if self._ring is not None:
            self._seal()
            self._ring.abandon()
            self._ring = self._array = None
            self.pub._end_loan()


class CopyLoan:
    """The same ``with ... as msg`` for a publisher that cannot lend its memory (Zenoh, ROS 2):
    ``msg``'s array is a fresh one, published as usual (one copy) when the block ends."""

    def __init__(self, pub: Any, msg_cls: type, shape: tuple[int, ...], dtype: Any, field: str, fields: dict[str, Any]):
        self.pub, self.msg_cls, self.field, self.fields = pub, msg_cls, field, fields
        self.array = np.zeros(tuple(int(d) for d in shape), np.dtype(dtype))
        self.msg: Any = None

    def __enter__(self) -> Any:
        self.msg = _message_around(self.msg_cls, self.array, self.field, self.fields)
        return self.msg

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.pub.publish(self.msg)


def loan_from(pub: Any, msg_cls: type, shape: tuple[int, ...], dtype: Any = np.uint8, field: str = "data", **fields: Any) -> Any:
    """A loaned message of ``pub``: in its ring slot if it has one (``Publisher.loan``), else a
    :class:`CopyLoan`; either way ``with loan_from(...) as msg:`` publishes when the block ends."""
    if hasattr(pub, "loan"):
        return pub.loan(msg_cls, shape, dtype, field, **fields)
    return CopyLoan(pub, msg_cls, shape, dtype, field, fields)

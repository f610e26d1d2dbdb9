"""Loaned messages for publishers (issue 34, item 2): the array lives in the ring slot."""
import numpy as np
import pytest

from emos import msgs as M
from emos.transport import ring as R
from emos.transport.loans import LOAN_META_BYTES
from emos.transport.pubsub import MessageTooLarge, Publisher, Subscriber, TopicTypeError

pytestmark = pytest.mark.unit


def _frame(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (480, 640, 3), dtype=np.uint8)


def test_a_loaned_image_is_written_in_place_and_arrives_intact(ctx):
    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam", depth=4)
    sub = Subscriber(ctx, "/cam", M.Image, queue_size=8, transient_local=True)
    frames = [_frame(i) for i in range(3)]
    for i, frame in enumerate(frames):
        with pub.loan(M.Image, shape=(480, 640, 3), encoding="rgb8") as msg:
            # The array is the ring slot itself: no copy happens at commit.
            slot_base = np.frombuffer(pub.ring.mm, np.uint8).__array_interface__["data"][0]
            at = msg.data.__array_interface__["data"][0] - slot_base
            assert at == pub.ring.pending_offset() + LOAN_META_BYTES
            msg.to_numpy()[:] = frame
            msg.header.frame_id = f"cam{i}"
    got = sub.take()
    assert [m.header.frame_id for m in got] == ["cam0", "cam1", "cam2"]
    for m, frame in zip(got, frames):
        assert (m.height, m.width, m.step, m.encoding) == (480, 640, 1920, "rgb8")
        assert np.array_equal(m.to_numpy(), frame)
    # The message lent inside the block is read-only after it: the slot belongs to readers.
    with pytest.raises(ValueError):
        msg.data[0] = 1


def test_a_loan_ended_by_an_exception_publishes_nothing_and_the_next_message_takes_its_number(ctx):
    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam", depth=2)
    sub = Subscriber(ctx, "/cam", M.Image, queue_size=8)
    with pytest.raises(KeyError), pub.loan(M.Image, shape=(480, 640, 3)) as msg:
        msg.data[:] = 7
        raise KeyError("camera unplugged")
    assert sub.take() == []
    assert pub.ring.head == 0
    frame = _frame(9)
    n = pub.publish(M.Image.from_numpy(frame))
    assert n == 0
    [m] = sub.take()
    assert np.array_equal(m.to_numpy(), frame)


def test_one_loan_at_a_time_and_no_publish_meanwhile(ctx):
    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam")
    with pub.loan(M.Image, shape=(4, 4, 3)):
        with pytest.raises(RuntimeError, match="loan"):
            pub.publish(M.Image.from_numpy(np.zeros((4, 4, 3), np.uint8)))
        with pytest.raises(RuntimeError, match="still open"):
            pub.loan(M.Image, shape=(4, 4, 3))
    pub.publish(M.Image.from_numpy(np.zeros((4, 4, 3), np.uint8)))  # usable again
    with pytest.raises(TopicTypeError, match="Image"):
        pub.loan(M.UInt8MultiArray, shape=(8,))


def test_a_generic_message_with_other_arrays_and_fields(ctx):
    pub = Publisher(ctx, "/arr", M.Float32MultiArray, publisher_id="a")
    sub = Subscriber(ctx, "/arr", M.Float32MultiArray, queue_size=4, transient_local=True)
    dims = [M.MultiArrayDimension(label="rows", size=1000, stride=3000), M.MultiArrayDimension(label="xyz", size=3, stride=3)]
    with pub.loan(M.Float32MultiArray, shape=(1000, 3), dtype=np.float32, layout=M.MultiArrayLayout(dim=dims)) as msg:
        msg.data[:] = np.arange(3000, dtype=np.float32).reshape(1000, 3)
    [m] = sub.take()
    assert m.data.shape == (1000, 3) and m.data.dtype == np.float32
    assert np.array_equal(m.data, np.arange(3000, dtype=np.float32).reshape(1000, 3))
    assert [d.label for d in m.layout.dim] == ["rows", "xyz"]
    # A field replaced by another array inside the block is copied after the loaned one.
    with pub.loan(M.Float32MultiArray, shape=(10,), dtype=np.float32) as msg:
        msg.data = np.full(5, 2.5, np.float32)
    [m] = sub.take()
    assert np.array_equal(m.data, np.full(5, 2.5, np.float32))


def test_a_loan_whose_field_would_convert_the_array_is_refused_clearly(ctx):
    pub = Publisher(ctx, "/raw", M.UInt8MultiArray, publisher_id="raw")
    # Its converter makes a uint8 copy, which would not be the slot.
    with pytest.raises(TypeError, match="UInt8MultiArray.data"), pub.loan(M.UInt8MultiArray, shape=(4, 4), dtype=np.float32):
        pass
    assert pub.ring.head == 0
    pub.publish(M.UInt8MultiArray(data=np.zeros(4, np.uint8)))  # the slot was given back


def test_metadata_too_big_for_the_room_before_the_array_is_refused_and_abandoned(ctx):
    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam")
    sub = Subscriber(ctx, "/cam", M.Image, queue_size=4, transient_local=True)
    with pytest.raises(MessageTooLarge, match="before its array"), pub.loan(M.Image, shape=(8, 8, 3)) as msg:
        msg.header.frame_id = "x" * (2 * LOAN_META_BYTES)
    assert sub.take() == []
    with pub.loan(M.Image, shape=(8, 8, 3)) as msg:
        msg.data[:] = 3
    [m] = sub.take()
    assert int(m.data.sum()) == 3 * 8 * 8 * 3


def test_a_loan_grows_the_ring_and_readers_follow(ctx):
    pub = Publisher(ctx, "/big", M.UInt8MultiArray, publisher_id="b", capacity=1024)
    sub = Subscriber(ctx, "/big", M.UInt8MultiArray, queue_size=4, transient_local=True)
    with pub.loan(M.UInt8MultiArray, shape=(3 << 20,)) as msg:
        msg.data[:] = 5
    assert pub.ring.capacity >= 3 << 20
    [m] = sub.take()
    assert m.data.nbytes == 3 << 20 and int(m.data[-1]) == 5
    assert R.Ring.attach(pub.segment) is not None


def test_loan_from_lends_the_ring_slot_or_falls_back_to_one_copy(ctx):
    from emos.transport.loans import CopyLoan, PublisherLoan, loan_from

    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam")
    assert isinstance(loan_from(pub, M.Image, (4, 4, 3)), PublisherLoan)

    class _NoLoans:  # a transport that cannot lend memory (Zenoh, ROS 2) has publish() only
        def __init__(self):
            self.sent = []

        def publish(self, msg):
            self.sent.append(msg)

    other = _NoLoans()
    loan = loan_from(other, M.Image, (4, 4, 3), encoding="bgr8")
    assert isinstance(loan, CopyLoan)
    with loan as msg:
        msg.to_numpy()[:] = 9
    [sent] = other.sent
    assert sent.encoding == "bgr8" and int(sent.data.min()) == 9
    with pytest.raises(ValueError), loan_from(other, M.Image, (4, 4, 3)) as msg:
        raise ValueError("dropped frame")
    assert len(other.sent) == 1

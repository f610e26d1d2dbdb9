"""The driver's hold mode of the node parser (bytes wait, unchecked, until a possible start flag)
delivers the same revolutions as checking every read, and never a node that was not sent."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.hardware.rplidar import protocol as P
from emos.actors.hardware.rplidar.scan import RevolutionStream

from .test_rplidar_protocol import _is_subsequence, _nodes

pytestmark = pytest.mark.unit


def _revolutions(stream: bytes, chunk: int, hold: bool) -> tuple[list, P.NodeParser]:
    rs = RevolutionStream()
    rs.parser = P.NodeParser(hold_until_start=hold)
    revs = []
    for i in range(0, len(stream), chunk):
        revs += rs.feed(stream[i:i + chunk])
    return revs, rs.parser


def _key(rev) -> tuple:
    n = rev.nodes
    return rev.clean, n.angle_q6.tobytes(), n.distance_q2.tobytes(), n.quality.tobytes()


@pytest.mark.parametrize("chunk", [7, 61, 512, 1800])
def test_clean_stream_same_revolutions_with_and_without_hold(chunk):
    start, q, a, d = _nodes(3600, np.random.default_rng(5), revs=10)
    raw = P.encode_nodes(start, q, a, d)
    held, hp = _revolutions(raw, chunk, hold=True)
    every, ep = _revolutions(raw, chunk, hold=False)
    assert [_key(r) for r in held] == [_key(r) for r in every] and len(held) == 9  # the 10th waits for a start
    assert hp.dropped == ep.dropped == 0


@pytest.mark.parametrize("seed", range(6))
def test_garbage_hold_mode_never_delivers_a_node_not_sent_and_loses_no_clean_revolution(seed):
    rng = np.random.default_rng(seed)
    start, q, a, d = _nodes(7200, rng, revs=20)
    raw = P.encode_nodes(start, q, a, d)
    truth = P.decode_nodes(raw)
    cuts = sorted(rng.choice(np.arange(1, len(raw)), 6, replace=False).tolist())
    pieces, prev = [], 0
    for c in cuts:
        pieces += [raw[prev:c], rng.integers(0, 256, int(rng.integers(1, 30))).astype(np.uint8).tobytes()]
        prev = c
    stream = b"".join([*pieces, raw[prev:]])
    held, hp = _revolutions(stream, 512, hold=True)
    every, ep = _revolutions(stream, 512, hold=False)
    for rev in held:
        assert _is_subsequence(rev.nodes, truth)
    assert hp.dropped == ep.dropped  # the same bytes are thrown away, checked later or not
    clean_held = [_key(r) for r in held if r.clean]
    clean_every = [_key(r) for r in every if r.clean]
    # a slip costs the revolutions on either side of it, whenever it is found: the same ones
    assert clean_held == clean_every and len(clean_held) >= 20 - 1 - 2 * len(cuts)

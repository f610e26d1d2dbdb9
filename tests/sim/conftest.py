import pytest

pybullet = pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")


@pytest.fixture
def make_world():
    """Factory for lock-step worlds, all closed at the end of the test."""
    from emos.actors.sim import SimClock, World

    worlds = []

    def factory(**kwargs):
        kwargs.setdefault("clock", SimClock(mode="lockstep"))
        w = World(**kwargs)
        worlds.append(w)
        return w

    yield factory
    for w in worlds:
        w.close()

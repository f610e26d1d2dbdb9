import pytest

from emos.transport.context import RunContext


@pytest.fixture
def ctx():
    """A private run for topic tests; everything it created is removed after."""
    c = RunContext.create()
    yield c
    c.remove_everything()


@pytest.fixture(params=["c", "python"])
def ring_path(request, monkeypatch):
    """Big messages through the C calls (``_ccodec.ring_write`` to publish, ``ring_loan`` to
    take; what users get where the codec is built) or through ring.py's Python path (every
    machine without a compiler, ``EMOS_CODEC=python``): the tests that use this run on both."""
    from emos.transport import loans, pubsub

    if request.param == "c":
        if pubsub._ring_write is None or loans._ring_loan is None:
            pytest.skip("the C codec is not built (no compiler at install, or EMOS_CODEC=python)")
    else:
        monkeypatch.setattr(pubsub, "_ring_write", None)
        monkeypatch.setattr(loans, "_ring_loan", None)
    return request.param

import pytest

from emos.transport.context import RunContext


@pytest.fixture
def ctx():
    """A private run for topic tests; everything it created is removed after."""
    c = RunContext.create()
    yield c
    c.remove_everything()

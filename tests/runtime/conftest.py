import pytest

from emos.transport.context import RunContext
from tests.runtime.helpers import kill_leftover_systems


@pytest.fixture
def ctx():
    """A private run for in-process topic tests; everything it created is removed after."""
    c = RunContext.create()
    yield c
    c.remove_everything()


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()

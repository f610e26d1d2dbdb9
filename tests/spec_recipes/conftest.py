import pytest

from tests.runtime.helpers import kill_leftover_systems


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()

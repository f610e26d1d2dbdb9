import pytest

from tests.runtime.helpers import kill_leftover_systems


@pytest.fixture(scope="session")
def model_server():
    """One real ``emos serve models`` for every component test of the session."""
    from tests.agents.fixtures.server_process import start_server

    proc = start_server()
    yield proc
    proc.stop()


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()

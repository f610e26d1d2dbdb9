import pytest

from tests.runtime.helpers import kill_leftover_systems


@pytest.fixture(scope="session")
def model_server():
    """One real ``emos serve models`` for every component test of the session."""
    import httpx

    from tests.agents.fixtures.server_process import start_server

    proc = start_server()
    # Load the server's embedding model now, once, rather than inside the first test that
    # embeds (importing sentence-transformers takes 5-30 s on a loaded 2-core machine).
    httpx.post(f"http://127.0.0.1:{proc.port}/v1/embeddings", json={"model": "all-minilm-l6-v2", "input": ["warm"]},
               timeout=180).raise_for_status()
    yield proc
    proc.stop()


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()

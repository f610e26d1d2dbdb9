"""Settings for every test, and the tiers every test module declares.

Each module sets ``pytestmark`` to its tiers (pyproject.toml lists them): ``unit`` (one process,
no process tree, simulator or browser: ``python3 -m pytest -m unit`` is the fast inner loop),
``process`` (starts runs, servers or the CLI), ``sim`` (a pybullet world), ``browser`` (headless
Chromium), and ``statistical`` beside one of those (rates over many trials)."""
import os
import tempfile

import pytest


@pytest.fixture(scope="session", autouse=True)
def _private_emos_home():
    """`emos run` keeps a log of each run in $EMOS_HOME/logs (default ~/emos): tests use a
    folder of their own, so running the suite neither fills nor reads the user's."""
    if os.environ.get("EMOS_HOME"):
        yield
        return
    with tempfile.TemporaryDirectory(prefix="emos-home-") as home:
        os.environ["EMOS_HOME"] = home
        try:
            yield
        finally:
            os.environ.pop("EMOS_HOME", None)


TIERS = ("unit", "process", "sim", "browser")


@pytest.fixture(autouse=True)
def _ctrl_c_left_as_found(request: pytest.FixtureRequest):
    """Every test leaves SIGINT's disposition and the signal mask as it found them. A child
    inherits an ignored SIGINT and a blocked mask: a test that left either behind (an in-process
    node or library that set SIGINT to SIG_IGN) made every later `emos ... ` subprocess of that
    worker deaf to Ctrl-C, and the Ctrl-C tests hung (seen in two full runs, never alone). The
    fixture puts them back and says which test changed them."""
    import signal
    import threading
    import warnings

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before, mask = signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, set())
    yield
    changed = []
    if signal.getsignal(signal.SIGINT) is not before:
        changed.append(f"SIGINT handler {signal.getsignal(signal.SIGINT)!r}")
        signal.signal(signal.SIGINT, before)
    if signal.pthread_sigmask(signal.SIG_BLOCK, set()) != mask:
        changed.append("the signal mask")
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    if changed:
        warnings.warn(f"{request.node.nodeid} left {' and '.join(changed)} behind; restored", stacklevel=1)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """A test without a tier would be in no loop but the full run: refuse to collect it."""
    untiered = sorted({item.nodeid.split("::")[0] for item in items if not any(item.get_closest_marker(t) for t in TIERS)})
    if untiered:
        raise pytest.UsageError(f"test modules without a tier marker ({', '.join(TIERS)}): {', '.join(untiered)}; "
                                "set pytestmark = pytest.mark.<tier> in each (see tests/conftest.py)")

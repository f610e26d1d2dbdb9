"""Settings for every test, and the tiers every test module declares.

Each module sets ``pytestmark`` to its tiers (pyproject.toml lists them): ``unit`` (one process,
no process tree, simulator or browser: ``python3 -m pytest -m unit`` is the fast inner loop),
``process`` (starts runs, servers or the CLI), ``sim`` (a pybullet world), ``browser`` (headless
Chromium), and ``statistical`` beside one of those (rates over many trials)."""
import os
import sys
import tempfile

import pytest

# pytest keeps each test module's assertion-rewritten code in __pycache__ unless bytecode writing is
# off: an environment with PYTHONDONTWRITEBYTECODE=1 made every xdist worker rewrite and compile all
# the test modules again at each collection (13 s of CPU per worker, 5 s from the cache). Only this
# process writes; the subprocesses the tests start inherit the environment as it is.
sys.dont_write_bytecode = False


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


class _NeedMarker(Exception):
    pass


def _marker_expression_can_hold(markexpr: str, unit: bool) -> bool:
    """Whether ``-m markexpr`` can select a test whose ``unit`` marker is ``unit``, whatever its
    other markers are: every assignment of the other markers the expression asks about is tried."""
    from _pytest.mark.expression import Expression

    expression = Expression.compile(markexpr)

    def holds(known: dict[str, bool]) -> bool:
        def matcher(name: str, **kwargs: object) -> bool:
            if name == "unit" and not kwargs:
                return unit
            if name not in known:
                raise _NeedMarker(name)
            return known[name]
        try:
            return expression.evaluate(matcher)
        except _NeedMarker as need:
            return holds({**known, str(need): True}) or holds({**known, str(need): False})

    return holds({})


def pytest_ignore_collect(collection_path, config: pytest.Config):
    """``-m unit`` (the inner loop) does not import the modules that cannot hold a unit test: a
    module's tiers are its ``pytestmark`` (and markers on its tests), so a test module whose text
    never says ``mark.unit`` has none, and importing it (torch, pybullet, a ROS 2 check) only
    cost each xdist worker its time. Any other selection collects as before."""
    markexpr = config.option.markexpr
    if not markexpr or collection_path.suffix != ".py" or not collection_path.name.startswith("test_"):
        return None
    try:
        if "mark.unit" in collection_path.read_text(encoding="utf-8"):
            return None
    except OSError:
        return None  # collected as usual: pytest reports what is wrong with the file
    return True if not _marker_expression_can_hold(markexpr, unit=False) else None


#: Fixtures that start a model server (``emos serve models``, which imports sentence-transformers and
#: loads the embedding model) once per xdist worker (session scope) or once per module on each worker
#: that runs one of its tests: at load 50 the recipe server's start took 230 s and 166 s, once on each
#: worker. Their tests share one worker (an xdist_group named after the fixture), which starts each
#: server once per run. Modules that load the embedding model in the test process say so themselves
#: (``xdist_group("embedder")``; tests/test_suite_groups.py keeps them in it).
SHARED_SERVER_FIXTURES = ("model_server", "recipe_server")


def pytest_itemcollected(item: pytest.Item) -> None:
    """Groups the tests of SHARED_SERVER_FIXTURES. Done as each test is collected, so the marker is
    there before pytest-xdist turns groups into test ids (in its pytest_collection_modifyitems,
    which may run before ours)."""
    for name in SHARED_SERVER_FIXTURES:
        if name in getattr(item, "fixturenames", ()) and not item.get_closest_marker("xdist_group"):
            item.add_marker(pytest.mark.xdist_group(name))
            break


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """A test without a tier would be in no loop but the full run: refuse to collect it. Then the
    long work first: modules with an xdist group (run serially on one worker), then those with
    process, sim or browser tests, then the unit modules, each module kept whole and in its place
    among its kind. pytest-xdist hands out work in this order (after its groups, largest first),
    so the last minutes of ``-n 2`` are short unit tests on both workers, not one worker finishing
    a 60 s navigation run while the other waits."""
    untiered = sorted({item.nodeid.split("::")[0] for item in items if not any(item.get_closest_marker(t) for t in TIERS)})
    if untiered:
        raise pytest.UsageError(f"test modules without a tier marker ({', '.join(TIERS)}): {', '.join(untiered)}; "
                                "set pytestmark = pytest.mark.<tier> in each (see tests/conftest.py)")

    def rank(item: pytest.Item) -> int:
        if item.get_closest_marker("xdist_group"):
            return 0
        return 1 if any(item.get_closest_marker(t) for t in ("process", "sim", "browser")) else 2

    module_rank: dict[str, int] = {}
    for item in items:
        module = item.nodeid.split("::")[0]
        module_rank[module] = min(module_rank.get(module, 2), rank(item))
    items.sort(key=lambda item: module_rank[item.nodeid.split("::")[0]])  # stable: the order within a rank stays

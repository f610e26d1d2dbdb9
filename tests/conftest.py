"""Settings for every test."""
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

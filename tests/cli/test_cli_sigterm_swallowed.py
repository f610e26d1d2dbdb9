"""A SIGTERM whose SystemExit Python swallowed still ends a command that loops until told to stop.

The CLI's SIGTERM handler raises SystemExit wherever the main thread is; inside a ``__del__``
(or a weakref or GC callback) Python prints "Exception ignored" and carries on. A SIGTERMed
``emos topic echo`` looped on for 23 minutes so. The handler also notes the signal, and the
echo, hz and pub loops check the note on every turn.
"""
from __future__ import annotations

import gc
import sys

import pytest

from emos.tools import cli
from emos.tools.cli import common

pytestmark = pytest.mark.unit


@pytest.fixture(autouse=True)
def _fresh_note():
    common._TERMINATED.clear()
    yield
    common._TERMINATED.clear()


class _SignalInDel:
    """Runs the SIGTERM handler inside __del__, where its SystemExit is swallowed."""

    def __del__(self) -> None:
        cli._terminated(15, None)


def test_a_swallowed_sigterm_still_ends_the_loop(monkeypatch):
    swallowed: list[BaseException | None] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: swallowed.append(u.exc_value))
    common.exit_if_terminated()  # nothing asked yet: carries on
    obj = _SignalInDel()
    del obj
    gc.collect()
    assert len(swallowed) == 1 and isinstance(swallowed[0], SystemExit)  # the SystemExit went nowhere
    with pytest.raises(SystemExit) as exc:
        common.exit_if_terminated()
    assert exc.value.code == 143


def test_the_handler_still_raises_where_it_can():
    with pytest.raises(SystemExit) as exc:
        cli._terminated(15, None)
    assert exc.value.code == 143

"""`emos bench barn --no-swept-check`: the BARN stack's DriveManager without the swept check
(the safety zones alone), to measure what the check changes (docs/safety.md)."""
from __future__ import annotations

import argparse

import pytest

from emos.tools.barn import add_arguments, run
from emos.tools.barn.stack import StackOptions, build_system, recipe_source

pytestmark = pytest.mark.unit


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(list(argv))


def test_the_option_turns_the_drive_managers_check_off():
    assert _args().swept_check is True
    assert _args("--no-swept-check").swept_check is False
    for on in (True, False):
        _, (_, _, _, driver) = build_system(StackOptions(world=3, swept_check=on))
        assert driver.config.swept_check is on
    # The trial's recipe (what `emos run` executes in the trial's processes) carries it.
    assert "'swept_check': False" in recipe_source(StackOptions(world=3, swept_check=False))


def test_an_in_process_run_refuses_it(capsys):
    assert run(_args("--in-process", "--no-swept-check", "--worlds", "1", "--seeds", "1")) == 2
    assert "no DriveManager" in capsys.readouterr().err

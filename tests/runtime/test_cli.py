"""The `emos` command line dispatches to lazily imported plug-ins."""
import subprocess
import sys

import pytest

from emos.tools import cli

pytestmark = pytest.mark.process


def test_every_plugin_table_entry_names_an_importable_module_path():
    for table in (cli.COMMANDS, cli.BENCHMARKS, cli.SERVICES):
        for name, (module, help_text) in table.items():
            assert module.startswith("emos."), name
            assert help_text


def test_help_lists_commands():
    out = subprocess.run([sys.executable, "-m", "emos", "--help"], capture_output=True, text=True, check=True)
    for word in ("run", "status", "topic", "bench", "serve"):
        assert word in out.stdout


def test_unknown_command_is_a_usage_error():
    out = subprocess.run([sys.executable, "-m", "emos", "nonsense"], capture_output=True, text=True)
    assert out.returncode == 2
    assert "invalid choice" in out.stderr

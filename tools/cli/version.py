"""``emos version``."""
from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "example:\n  emos version      # emos 0.1.0 (python 3.11.2)\n"


def run(args: argparse.Namespace) -> int:
    import emos

    print(f"emos {emos.__version__} (python {sys.version.split()[0]})")
    return 0

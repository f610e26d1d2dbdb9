"""``emos version``."""
from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "example:\n  emos version      # emos 0.1.0 (python 3.11.2)\n"


def run(args: argparse.Namespace) -> int:
    import emos
    from emos.interop.ros2 import env as ros2_env

    print(f"emos {emos.__version__} (python {sys.version.split()[0]})")
    print(ros2_env.describe())  # which ROS 2 `emos run --ros2` would use, or what to install
    return 0

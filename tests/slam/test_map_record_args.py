"""`emos map record`: `emos record` of the scan and odometry topics, for `emos map build`."""
from __future__ import annotations

import argparse

import pytest

from emos.tools.cli import map as map_cli

pytestmark = pytest.mark.unit


def _parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="emos map")
    map_cli.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_map_record_records_the_scan_and_odometry_topics_by_default() -> None:
    args = map_cli.record_args(_parse("record", "-o", "run.mcap"))
    assert args.topics == ["/scan", "/odom"]
    assert args.output == "run.mcap"


def test_map_record_takes_other_topic_names_and_every_record_option() -> None:
    args = map_cli.record_args(_parse("record", "-o", "run.mcap", "--scan", "/base_scan", "--odom", "/wheel_odom",
                                      "--duration", "30", "--compression", "zstd"))
    assert args.topics == ["/base_scan", "/wheel_odom"]
    assert args.duration == 30.0 and args.compression == "zstd"
    named = map_cli.record_args(_parse("record", "-o", "run.mcap", "/scan", "/odom", "/tf"))
    assert named.topics == ["/scan", "/odom", "/tf"]


def test_map_record_needs_an_output_file() -> None:
    with pytest.raises(SystemExit):
        _parse("record")

"""``emos bench hardware``: the three drivers against their emulators (docs/hardware.md).

* ``/cmd_vel`` published -> Drive Direct bytes read by the emulated Create 2, through a real
  ``emos run`` process holding the Create 2 plugin (p50 / p99 ms over ``--commands``);
* the RPLIDAR driver reading an emulator process at its 10 Hz: scans per second and corrupt
  scans over ``--scans`` revolutions; and the parse CPU per scan of ours (the driver's reads of
  512 bytes, its node parser) against pyrplidar's per-node decode of the same byte stream;
* the Feetech bus: full 6-joint SYNC_READ + SYNC_WRITE cycles per second at 1 Mbaud emulated.

``--json`` prints exactly ``{"cmd_to_wire_p50_ms", "cmd_to_wire_p99_ms", "scans_per_s",
"corrupt_scans", "parse_cpu_ratio_vs_pyrplidar", "servo_cycle_hz"}``.
"""
from __future__ import annotations

import argparse
import json
from typing import Any

KEYS = ("cmd_to_wire_p50_ms", "cmd_to_wire_p99_ms", "scans_per_s", "corrupt_scans", "parse_cpu_ratio_vs_pyrplidar",
        "servo_cycle_hz")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--commands", type=int, default=300, help="Twists to time through the Create 2 plugin (default 300)")
    parser.add_argument("--scans", type=int, default=50, help="lidar revolutions to read from the emulator (default 50)")
    parser.add_argument("--servo-seconds", type=float, default=3.0, help="seconds of servo bus cycles (default 3)")
    parser.add_argument("--chunk", type=int, default=512, help="bytes per read in the parse comparison (the driver's, default 512)")
    parser.add_argument("--json", action="store_true", help="print only the JSON result")


def measure(commands: int = 300, scans: int = 50, servo_seconds: float = 3.0, chunk: int = 512) -> dict[str, Any]:
    from emos.actors.hardware.create2.bench import bench_cmd_to_wire
    from emos.actors.hardware.feetech.bench import servo_cycle_hz
    from emos.actors.hardware.rplidar.bench import live_cost, parse_cost

    for name, value in (("commands", commands), ("scans", scans)):
        if value < 1:
            raise ValueError(f"bench hardware: --{name} must be >= 1, got {value}")
    detail: dict[str, Any] = {}
    detail["create2"] = bench_cmd_to_wire(commands)
    detail["rplidar_live"] = live_cost(scans, against_pyrplidar=False)
    detail["rplidar_parse"] = parse_cost(chunk=chunk)
    detail["feetech"] = servo_cycle_hz(servo_seconds)
    result = {
        "cmd_to_wire_p50_ms": detail["create2"]["cmd_to_wire_p50_ms"],
        "cmd_to_wire_p99_ms": detail["create2"]["cmd_to_wire_p99_ms"],
        "scans_per_s": round(detail["rplidar_live"]["scans_per_s"], 2),
        "corrupt_scans": int(detail["rplidar_live"]["corrupt_scans"]),
        "parse_cpu_ratio_vs_pyrplidar": (None if detail["rplidar_parse"]["parse_cpu_ratio_vs_pyrplidar"] is None
                                         else round(detail["rplidar_parse"]["parse_cpu_ratio_vs_pyrplidar"], 2)),
        "servo_cycle_hz": round(detail["feetech"]["servo_cycle_hz"], 1),
    }
    return {"result": result, "detail": detail}


def run(args: argparse.Namespace) -> int:
    out = measure(args.commands, args.scans, args.servo_seconds, args.chunk)
    result = out["result"]
    if args.json:
        print(json.dumps({k: result[k] for k in KEYS}))
        return 0
    d = out["detail"]
    rows = [
        ("/cmd_vel -> Drive Direct on the wire, p50", f"{result['cmd_to_wire_p50_ms']:.3f} ms", f"{d['create2']['commands']} commands, one emos run process"),
        ("/cmd_vel -> Drive Direct on the wire, p99", f"{result['cmd_to_wire_p99_ms']:.3f} ms", f"max {d['create2']['cmd_to_wire_max_ms']:.3f} ms"),
        ("RPLIDAR scans per second", f"{result['scans_per_s']:.2f}", f"{d['rplidar_live']['scans']} scans from a 10 Hz emulator"),
        ("RPLIDAR corrupt scans", f"{result['corrupt_scans']}", "delivered scans with a dropped byte: must be 0"),
        ("parse CPU per scan: ours / pyrplidar", f"{d['rplidar_parse']['ours_parse_us_per_scan']:.1f} / "
         f"{d['rplidar_parse']['pyrplidar_us_per_scan'] or float('nan'):.1f} us",
         f"ratio {result['parse_cpu_ratio_vs_pyrplidar']} (goal >= 5), {args.chunk}-byte reads"),
        ("servo bus cycle (6 joints, 1 Mbaud)", f"{result['servo_cycle_hz']:.1f} Hz", "goal >= 200 Hz"),
    ]
    width = max(len(r[0]) for r in rows)
    for name, value, note in rows:
        print(f"{name:<{width}}  {value:>18}  {note}")
    return 0

"""Sensor faults applied in a real component's publish path, switched through its control socket."""
import random
import time

import numpy as np
import pytest

from emos.chaos.history import History
from emos.chaos.nemesis.sensor import SensorFault
from emos.chaos.scenario import PROJECT_ROOT
from emos.chaos.target import RunningSystem
from emos.core.node import control_socket
from emos.core.rpc import RpcClient
from emos.msgs import LaserScan
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber

pytestmark = pytest.mark.process  # each test runs the soak recipe under the supervisor

SOAK = PROJECT_ROOT / "chaos" / "recipes" / "soak.py"


def _system(tmp_path, chaos: bool) -> RunningSystem:
    system = RunningSystem(SOAK, duration=60, log_path=tmp_path / "run.log", env={"EMOS_CHAOS": "1" if chaos else "0"})
    system.start()
    return system


def _scans(system, seconds=0.6, at_least=0):
    """The scans of ``seconds`` (wall), and on until ``at_least`` came: a busy machine publishes
    fewer in a given wall time, and a check of what the scans look like needs some (60 s: a hang)."""
    sub = Subscriber(RunContext(system.run_id, system.run_dir, owner=False), "/scan", LaserScan, queue_size=100)
    try:
        out, end, hang = [], time.monotonic() + seconds, time.monotonic() + 60.0
        while time.monotonic() < end or (len(out) < at_least and time.monotonic() < hang):
            out += sub.take()
            time.sleep(0.01)
        return out
    finally:
        sub.close()


def test_nan_truncate_stall_then_clean_again(tmp_path):
    system = _system(tmp_path, chaos=True)
    try:
        history = History()
        nan = SensorFault(component="lidar", topic="/scan", mode="nan", fraction=0.5)
        nan.bind(system, history, random.Random(1))
        assert nan.start() is not None
        time.sleep(0.2)
        scans = _scans(system, at_least=3)  # the first may be from before the fault
        assert scans and all(np.isnan(s.ranges).sum() == 360 for s in scans[1:])
        nan.stop()
        trunc = SensorFault(component="lidar", topic="/scan", mode="truncate", fraction=0.25)
        trunc.bind(system, history, random.Random(1))
        trunc.start()
        time.sleep(0.2)
        assert {len(s.ranges) for s in _scans(system, at_least=3)[1:]} == {540}
        trunc.stop()
        stall = SensorFault(component="lidar", topic="/scan", mode="stall")
        stall.bind(system, history, random.Random(1))
        stall.start()
        time.sleep(0.2)
        assert _scans(system) == []
        stall.stop()
        time.sleep(0.2)
        clean = _scans(system, at_least=2)
        assert clean and all(len(s.ranges) == 720 and not np.isnan(s.ranges).any() for s in clean)
        assert [r.detail["stale"] for r in history.of("fault")] == [False, False, True]
    finally:
        system.stop()


def test_injection_is_refused_outside_a_chaos_run(tmp_path):
    system = _system(tmp_path, chaos=False)
    try:
        ctx = RunContext(system.run_id, system.run_dir, owner=False)
        with RpcClient(control_socket(ctx, "lidar"), timeout=5.0) as rpc:
            with pytest.raises(Exception, match="fault injection is disabled"):
                rpc.call("inject_fault", topic="/scan", mode="nan", params={})
            with pytest.raises(Exception, match="publishes no '/odom'"):
                rpc.call("inject_fault", topic="/odom", mode="nan", params={})
    finally:
        system.stop()

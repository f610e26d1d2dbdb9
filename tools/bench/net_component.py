"""``emos bench net --mode component``: ping-pong between two real runs over Zenoh.

The transport mode measures :class:`ZenohPublisher` / :class:`ZenohSubscriber` under a hand-made
loop. This mode measures what a user gets: two runs (each its own supervised ``System``, run id
and Zenoh session, sharing nothing but Zenoh over loopback TCP), one with an Echo component and
one with a Ping component, their topics declared ``transport="zenoh"`` with the default QoS. Each
message goes through the whole node path: Zenoh's thread checks and decodes it and pokes the
node's wake-up FIFO, uvloop wakes the node, the node runs the Event-triggered
``_execution_step``, which publishes; each run's supervisor watches its component's status stream
and its Zenoh helper repeats it over Zenoh, as in any run with ``--zenoh``. The components are :mod:`ipc_component`'s, so replies are checked
by sequence number and the first of each size byte for byte.

Both runs are spawned processes (fresh interpreters): the benchmark process may have used Zenoh
already, and a Zenoh runtime does not survive a fork.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import signal
import tempfile
from pathlib import Path
from typing import Any

from emos.tools.bench.ipc_pingpong import warmup_round_trips

LABEL = "emos-zenoh-component"


def _run_main(role: str, plan: list[tuple[int, int]], result_path: str, config: str, group: str, parent: int) -> None:
    """One run: a supervised System holding the ``role`` component, on Zenoh ``config``."""
    from emos.core.prctl import die_with, set_process_name
    from emos.supervisor.system import Package, System, SystemOptions

    set_process_name(f"emos:bench-net-{role}")
    os.environ["EMOS_ZENOH_CONFIG"] = config
    os.environ["EMOS_NET_GROUP"] = group
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the benchmark stops its runs itself
    if not die_with(parent, signal.SIGTERM):
        os._exit(1)
    from emos.tools.bench.ipc_component import _components

    echo, ping = _components(plan, result_path, None, transport="zenoh", label=LABEL)
    system = System([Package(components=[echo if role == "echo" else ping], multiprocessing=True)], SystemOptions(heartbeat_timeout=5.0))
    os._exit(system.run())


def latency(sizes: list[int], messages_for: Any, configs: tuple[str, str], group: str) -> tuple[list[dict[str, Any]], str | None]:
    """One row per size (``transport``: :data:`LABEL`), and an error (None if every reply was the
    one expected). ``configs``: the Zenoh configuration files of the ping and the echo run."""
    from emos.tools.bench.ipc_component import await_result, check_sizes

    too_small = check_sizes(sizes)
    if too_small:
        return [], too_small
    plan = [(size, messages_for(size)) for size in sizes]
    budget = 90.0 + sum((warmup_round_trips(n) + n) * (0.02 + size / 2e7) for size, n in plan)
    spawn = mp.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="emos-bench-net-") as tmp:
        result_path = str(Path(tmp) / "result.json")
        runs = {
            f"{role} run": spawn.Process(target=_run_main, args=(role, plan, result_path, config, group, os.getpid()), name=f"emos-bench-net-{role}", daemon=True)
            for role, config in (("echo", configs[1]), ("ping", configs[0]))
        }
        for proc in runs.values():
            proc.start()
        return await_result(runs, result_path, budget)

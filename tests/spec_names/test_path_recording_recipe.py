"""End to end: recipes/path_recording.py (the spec's path-recording page, its imports and simulator
lines changed) records a driven path, saves it and the computed plan, and loads a file back as the
global plan, through the Planner's services called with the recipe's own ``ServiceClientConfig``
definitions; the web UI shows the three services as inputs and calls one from its form.

The recipe's text runs as written except for the UI port (a free one instead of the page's
5001, which another run may hold)."""
from __future__ import annotations

import asyncio
import csv
import math
import re

import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = [pytest.mark.sim, pytest.mark.process]

RECIPE = REPO / "recipes" / "path_recording.py"
GOAL = (0.0, 2.0)  # in the TurtleBot3 arena, 2 m from where the robot starts (0, 0), in free space
TOKEN = "spec-names-path-recording-token"


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _services():
    """The recipe's three ServiceClientConfig definitions, as it writes them."""
    from emos import ServiceClientConfig
    from emos.actors.nav.components.interfaces import PathFromToFile, StartPathRecording

    node_name = "planner"
    return (ServiceClientConfig(name=f"{node_name}/save_plan_to_file", srv_type=PathFromToFile),
            ServiceClientConfig(name=f"{node_name}/load_plan_from_file", srv_type=PathFromToFile),
            ServiceClientConfig(name=f"{node_name}/start_path_recording", srv_type=StartPathRecording))


def _rows(path) -> list[tuple[float, float, float]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["x", "y", "yaw"], rows[:2]
    return [tuple(float(v) for v in r) for r in rows[1:]]


def _ui(port: int, service: str, value: dict) -> tuple[list[str], list[dict]]:
    """The page's inputs (layout), then one call of ``service`` from its form over the websocket."""
    import aiohttp

    async def page() -> tuple[list[str], list[dict]]:
        headers = {"Authorization": f"Bearer {TOKEN}"}
        async with aiohttp.ClientSession(headers=headers, cookie_jar=aiohttp.CookieJar(unsafe=True)) as session:
            async with session.get(f"http://127.0.0.1:{port}/api/layout") as r:
                inputs = [i["topic"] for i in (await r.json())["inputs"]]
            async with session.get(f"http://127.0.0.1:{port}/api/session") as r:
                csrf = (await r.json())["csrf"]
            states: list[dict] = []
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws", params={"csrf": csrf}) as ws:
                await ws.send_json({"op": "goal", "id": 1, "topic": service, "value": value})
                while not states or states[-1]["state"] == "sent":
                    msg = await ws.receive(timeout=60)
                    if msg.type == aiohttp.WSMsgType.TEXT:
                        data = msg.json()
                        if data.get("op") == "result":
                            assert data["ok"], data
                        elif data.get("op") == "action" and data.get("topic") == service:
                            states.append(data)
            return inputs, states

    return asyncio.run(page())


def test_path_recording_recipe_records_saves_and_loads_paths(tmp_path):
    from emos.transport.pubsub import Publisher, Subscriber

    source = RECIPE.read_text()
    assert source.count("launcher.enable_ui(\n") == 1, "the recipe's enable_ui call changed: update this test"
    port = _free_port()
    source = source.replace("launcher.enable_ui(\n", f"launcher.enable_ui(port={port},\n")
    system = SystemUnderTest(tmp_path, source, env={"EMOS_UI_TOKEN": TOKEN})
    system.wait_up(timeout=120, components=["planner", "controller", "drive_manager", "global_map_server", "sim", "ui"])
    save, load, record = _services()
    odom = Subscriber(system.ctx, "/odometry/filtered", M.Odometry, queue_size=1000)
    plan = Subscriber(system.ctx, "/plan", M.Path, queue_size=100)
    goal = Publisher(system.ctx, "/goal", M.PointStamped, publisher_id="test_operator")
    try:
        # Option B of the page: record while the robot drives (here: to a goal the planner plans to)
        started = record.call(recording_time_step=0.1, ctx=system.ctx)
        assert started.success, started.message
        start = wait_until(lambda: odom.take()[-1:], timeout=60, what="odometry")[0].pose.pose.position
        goal.publish(M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=GOAL[0], y=GOAL[1])))

        def moved() -> bool:
            got = odom.take()
            return bool(got) and math.dist((got[-1].pose.pose.position.x, got[-1].pose.pose.position.y), (start.x, start.y)) > 0.8

        wait_until(moved, timeout=120, interval=0.2, what="the robot to drive 0.8 m towards the goal")
        driven = save.call(file_location=str(tmp_path), file_name="driven_path.csv", ctx=system.ctx)
        assert driven.success and "recorded path" in driven.message, driven.message
        rows = _rows(tmp_path / "driven_path.csv")
        assert len(rows) >= 5 and math.dist(rows[0][:2], rows[-1][:2]) > 0.6, rows  # the robot's track, not the plan
        assert math.dist(rows[0][:2], (start.x, start.y)) < 0.3

        # Option A: saving is not recording any more (save stopped it): the computed plan is saved
        computed = save.call(file_location=str(tmp_path), file_name="computed_path.csv", ctx=system.ctx)
        assert computed.success and computed.message.startswith("plan of"), computed.message
        plan_rows = _rows(tmp_path / "computed_path.csv")
        assert math.dist(plan_rows[-1][:2], GOAL) < 0.3, plan_rows[-1]

        # Replay: the loaded file is published as the global plan at once
        plan.take()
        loaded = load.call(file_location=str(tmp_path), file_name="driven_path.csv", ctx=system.ctx)
        assert loaded.success, loaded.message
        published = wait_until(lambda: plan.take()[-1:], timeout=30, what="the loaded plan on /plan")[0]
        xy = [(p.pose.position.x, p.pose.position.y) for p in published.poses]
        assert len(xy) == len(rows) and all(math.dist(a, b[:2]) < 1e-6 for a, b in zip(xy, rows))
        missing = load.call(file_location=str(tmp_path), file_name="nope.csv", ctx=system.ctx)
        assert not missing.success and "nope.csv" in missing.message

        # The web UI: the three services are its inputs, and its form calls them
        inputs, states = _ui(port, "planner/save_plan_to_file", {"file_location": str(tmp_path), "file_name": "from_ui.csv"})
        assert {"planner/save_plan_to_file", "planner/load_plan_from_file", "planner/start_path_recording"} <= set(inputs), inputs
        assert states[-1]["state"] == "succeeded" and states[-1]["value"]["success"], states
        assert _rows(tmp_path / "from_ui.csv") == rows  # the plan now is the loaded file
    finally:
        goal.close()
        odom.close()
        plan.close()
    assert system.stop() == 0, system.output()[-3000:]
    assert not re.search(r"Traceback", system.output()), system.output()[-5000:]

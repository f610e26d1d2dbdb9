"""Issue 41 item 3: the REST and WebSocket API and its OpenAPI document, against a running
system over HTTPS: inputs, services, action goals with feedback and cancel, subscriptions at
the client's rate, the supervision tree, logs and the system graph; wrong types refused with
the field named and nothing published; and a schema-based generator (schemathesis) finding no
5xx anywhere in the document."""
from __future__ import annotations

import asyncio
import json
import time

import aiohttp
import pytest

from tests.runtime.helpers import wait_until
from tests.ui_security.conftest import bearer, client_ssl, request

pytestmark = [pytest.mark.process, pytest.mark.timeout(240)]


@pytest.fixture
def api(secured):
    return secured  # the HTTPS system shared by this folder's tests (conftest.py)


WRONG = [  # path, body, the field the 422 must name
    ("/api/v1/inputs/question", {"value": 5}, "body.value"),
    ("/api/v1/inputs/question", {"value": "fine", "extra": 1}, "body.extra"),
    ("/api/v1/inputs/question", {}, "body.value"),
    ("/api/v1/inputs/speed", {"value": "fast"}, "body.value"),
    ("/api/v1/inputs/speed", {"value": True}, "body.value"),
    ("/api/v1/inputs/estop", {"value": "yes"}, "body.value"),
    ("/api/v1/inputs/cmd", {"value": {"linear": {"x": "fast"}}}, "body.value.linear.x"),
    ("/api/v1/inputs/cmd", {"value": {"linera": {"x": 1.0}}}, "body.value.linera"),
    ("/api/v1/inputs/goal", {"value": {"x": 1.0}}, "body.value.y"),
    ("/api/v1/inputs/goal", {"value": {"x": 1.0, "y": [2]}}, "body.value.y"),
    ("/api/v1/services/lamp/set", {"request": {"data": "on"}}, "body.request.data"),
    ("/api/v1/actions/navigator/action/goals", {"goal": {"x": "a", "y": 1.0}}, "body.goal.x"),
    ("/api/v1/actions/navigator/action/goals", {"goal": {"header": {"frame_id": 7}}}, "body.goal.header.frame_id"),
]


def test_wrong_types_are_refused_with_the_field_named_and_nothing_published(api):
    h = bearer(api.token)
    before = len(api.received())
    for path, body, field in WRONG:
        status, answer, _ = request(api, "POST", path, h, json_body=body)
        assert status == 422 and answer["field"] == field and field in answer["error"], (path, body, status, answer)
    status, answer, _ = request(api, "POST", "/api/v1/inputs/question", {**h, "Content-Type": "application/json"}, data=b"{not json")
    assert status == 400 and "not JSON" in answer["error"], answer
    status, answer, _ = request(api, "POST", "/api/v1/inputs/question", {**h, "Content-Type": "text/plain"}, data=b'{"value": "x"}')
    assert status == 415, answer
    assert request(api, "POST", "/api/v1/inputs/nosuch", h, json_body={"value": 1})[0] == 404
    time.sleep(1.0)  # what a wrong request published would have arrived by now
    assert [r for r in api.received()[before:] if r["topic"] != "navigate"] == [], api.received()[before:]
    # The same inputs with the right types: published, and received by the recipe.
    for path, body in (("/api/v1/inputs/question", {"value": "hello"}), ("/api/v1/inputs/speed", {"value": 0.5}),
                       ("/api/v1/inputs/estop", {"value": True}), ("/api/v1/inputs/cmd", {"value": {"linear": {"x": 0.3}, "angular": {"z": -0.2}}}),
                       ("/api/v1/inputs/goal", {"value": {"x": 1.5, "y": -2.0}})):
        status, answer, _ = request(api, "POST", path, h, json_body=body)
        assert status == 200 and answer == {"ok": True}, (path, answer)
    got = wait_until(lambda: {r["topic"]: r["value"] for r in api.received()[before:] if r["topic"] != "navigate"}
                if len([r for r in api.received()[before:] if r["topic"] != "navigate"]) >= 6 else None, what="the five inputs and the event")
    assert got["/question"] == "hello" and got["/speed"] == 0.5 and got["/estop"] is True
    assert got["/cmd"] == [0.3, -0.2] and got["/goal"] == [1.5, -2.0]
    assert got["estop-event"] is True  # the recipe's event fired on the published estop


def test_services_and_action_goals_with_feedback_and_cancel(api):
    h = bearer(api.token)
    status, answer, _ = request(api, "POST", "/api/v1/services/lamp/set", h, json_body={"request": {"data": True}})
    assert status == 200 and answer["ok"] and answer["response"] == {"success": True, "message": "lamp on"}, answer
    status, answer, _ = request(api, "POST", "/api/v1/actions/navigator/action/goals", h, json_body={"goal": {"x": 2.0, "y": 3.0}})
    assert status == 202 and answer["state"] == "sent", answer
    goal_id = answer["goal_id"]

    def done():
        s, a, _ = request(api, "GET", f"/api/v1/actions/navigator/action/goals/{goal_id}", h)
        return a if s == 200 and a["state"] in ("succeeded", "failed", "canceled") else None
    final = wait_until(done, what="the goal's result")
    assert final["state"] == "succeeded" and final["result"] == {"data": "reached 2.00 3.00"}, final
    assert [f["data"] for f in final["feedback"]] == [3.0, 2.0, 1.0], final
    # A long goal, cancelled.
    status, answer, _ = request(api, "POST", "/api/v1/actions/navigator/action/goals", h, json_body={"goal": {"x": 60.0, "y": 0.0}})
    long_id = answer["goal_id"]
    wait_until(lambda: request(api, "GET", f"/api/v1/actions/navigator/action/goals/{long_id}", h)[1]["feedback"], what="first feedback")
    status, answer, _ = request(api, "POST", f"/api/v1/actions/navigator/action/goals/{long_id}/cancel", h, json_body={})
    assert status == 202, answer
    final = wait_until(lambda: (lambda a: a if a["state"] != "running" and a["state"] != "sent" else None)(
        request(api, "GET", f"/api/v1/actions/navigator/action/goals/{long_id}", h)[1]), what="the cancel")
    assert final["state"] == "canceled", final
    assert request(api, "POST", f"/api/v1/actions/navigator/action/goals/{long_id}/cancel", h, json_body={})[0] == 409
    assert request(api, "GET", "/api/v1/actions/navigator/action/goals/" + "0" * 32, h)[0] == 404
    # The websocket: a goal with its feedback as it comes.
    msgs = ws_exchange(api, [{"op": "goal", "id": 1, "topic": "navigator/action", "value": {"x": 1.0, "y": 1.0}}], until=lambda m: m.get("state") == "succeeded")
    states = [m.get("state") for m in msgs if m.get("op") == "action"]
    assert states[0] == "sent" and "feedback" in states and states[-1] == "succeeded", msgs


def ws_exchange(api, sends: list[dict], until, seconds: float = 30.0) -> list[dict]:
    async def go() -> list[dict]:
        conn = aiohttp.TCPConnector(ssl=client_ssl(api.cert))
        async with aiohttp.ClientSession(connector=conn) as s, \
                s.ws_connect(api.base.replace("https", "wss") + "/api/v1/ws", headers=bearer(api.token)) as ws:
            for m in sends:
                await ws.send_json(m)
            got: list[dict] = []
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    got.append(await ws.receive_json(timeout=max(0.01, end - time.monotonic())))
                except TimeoutError:
                    break
                if until(got[-1]):
                    break
            return got
    return asyncio.run(go())


def test_subscriptions_at_the_clients_rate(api):
    # The talker publishes at 5 Hz; asked for 1 Hz, a client gets at most one sample a second.
    msgs = ws_exchange(api, [{"op": "subscribe", "id": 1, "topic": "words", "rate": 1.0}], until=lambda m: False, seconds=3.0)
    samples = [m for m in msgs if m.get("op") == "sample"]
    assert msgs[0] == {"op": "result", "id": 1, "ok": True} or any(m.get("op") == "result" and m["ok"] for m in msgs), msgs
    assert 1 <= len(samples) <= 4 and all(s["value"] == "still talking" and s["topic"] == "/words" for s in samples), samples
    seqs = [s["seq"] for s in samples]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    bad = ws_exchange(api, [{"op": "subscribe", "id": 2, "topic": "words", "rate": 0}, {"op": "subscribe", "id": 3, "topic": "nosuch"}],
                      until=lambda m: m.get("id") == 3, seconds=10.0)
    assert bad[0]["ok"] is False and bad[0]["field"] == "rate" and bad[1]["field"] == "topic", bad
    status, latest, _ = request(api, "GET", "/api/v1/outputs/words/latest", bearer(api.token))
    assert status == 200 and latest["value"] == "still talking" and latest["seq"] > 0, latest


def test_supervision_tree_logs_graph_and_the_document(api):
    h = bearer(api.token)
    status, tree, _ = request(api, "GET", "/api/v1/system", h)
    names = json.dumps(tree)
    assert status == 200 and all(f'"{n}"' in names for n in ("talker", "recorder", "lamp", "navigator", "ui")), tree
    status, logs, _ = request(api, "GET", "/api/v1/logs?lines=500", h)
    assert status == 200 and isinstance(logs["events"], list) and logs["events"], logs
    assert any("system up" in line for line in logs["lines"]), logs["lines"][-20:]
    assert request(api, "GET", "/api/v1/logs?lines=lots", h)[0] == 400
    status, graph, _ = request(api, "GET", "/api/v1/graph", h)
    comps = {c["name"]: c for c in graph["components"]}
    assert comps["talker"]["publishes"] == ["/words"] and "/question" in comps["recorder"]["subscribes"], graph
    assert {"name": "/words", "type": "String"} in graph["topics"]
    event = next(e for e in graph["events"] if e["name"] == "estop pressed")
    assert event["topics"] == ["/estop"] and event["actions"][0]["name"] == "note_estop" and event["actions"][0]["component"] == "recorder", event
    status, doc, _ = request(api, "GET", "/api/v1/openapi.json", h)
    assert status == 200 and doc["openapi"].startswith("3.1")
    for path in ("/api/v1/inputs/question", "/api/v1/inputs/cmd", "/api/v1/services/lamp/set", "/api/v1/actions/navigator/action/goals",
                 "/api/v1/actions/navigator/action/goals/{goal_id}/cancel", "/api/v1/outputs/words/latest", "/api/v1/system", "/api/v1/logs"):
        assert path in doc["paths"], path
    cmd = doc["paths"]["/api/v1/inputs/cmd"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert cmd["properties"]["value"]["properties"]["linear"]["properties"]["x"] == {"type": "number"}
    assert request(api, "GET", "/api/v1/openapi.json")[0] == 401  # the document needs a credential too


def test_schemathesis_finds_no_server_error(api):
    """Every operation of the served document, with generated valid and invalid data: no 5xx."""
    schemathesis = pytest.importorskip("schemathesis")
    from hypothesis import HealthCheck, Phase, given, settings

    status, doc, _ = request(api, "GET", "/api/v1/openapi.json", bearer(api.token))
    assert status == 200
    schema = schemathesis.openapi.from_dict(doc)
    seen: list[tuple[str, str, int]] = []
    for result in schema.get_all_operations():
        operation = result.ok()
        for mode in (schemathesis.GenerationMode.POSITIVE, schemathesis.GenerationMode.NEGATIVE):
            @settings(max_examples=5, deadline=None, database=None, phases=[Phase.generate], suppress_health_check=list(HealthCheck))
            @given(case=operation.as_strategy(generation_mode=mode))
            def call(case) -> None:
                response = case.call(base_url=api.base, headers=bearer(api.token), verify=str(api.cert), timeout=30)
                seen.append((case.method, case.path, response.status_code))
                assert response.status_code < 500, (case.method, case.formatted_path, case.body, response.status_code, response.text[:500])
            call()
    assert len({(m, p) for m, p, _ in seen}) >= 15, seen  # every operation was called
    assert any(code == 200 for _, _, code in seen) and any(400 <= code < 500 for _, _, code in seen)

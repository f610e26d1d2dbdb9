"""Issue 41: component settings and start/stop/restart through /api/v1, over real HTTPS, with
device tokens of both roles: viewers read the settings and get 403 on every change; operators
change settings (checked against the component's schema: 422 naming the parameter) and stop and
start components (404 naming an unknown one). The change is checked on the component itself,
through its control socket, not only through the API's answer."""
from __future__ import annotations

from pathlib import Path

import pytest

from emos.core.rpc import RpcClient
from tests.runtime.helpers import wait_until
from tests.ui_security.conftest import bearer, paired_operator, request, run_id_of

pytestmark = [pytest.mark.process, pytest.mark.timeout(240)]


def _control(secured, name: str, method: str, **kw):
    from emos.transport.context import runtime_root

    with RpcClient(Path(runtime_root()) / run_id_of(secured) / "ctl" / f"{name}.sock", timeout=5.0) as rpc:
        return rpc.call(method, **kw)


def test_settings_and_lifecycle_through_the_api_by_role(secured):
    viewer = bearer(paired_operator(secured, role="viewer", name="settings viewer"))
    operator = bearer(paired_operator(secured, role="operator", name="settings operator"))
    before = _control(secured, "talker", "info")["config"]["heartbeat_rate"]

    # Everyone signed in reads the forms, the values and the schemas.
    status, body, _ = request(secured, "GET", "/api/v1/settings", viewer)
    assert status == 200, body
    comps = {c["component"]: c for c in body["components"]}
    assert {"talker", "recorder", "lamp", "navigator"} <= set(comps) and "ui" not in comps, sorted(comps)
    talker = comps["talker"]
    assert talker["values"]["heartbeat_rate"] == before and "error" not in talker, talker
    assert talker["schema"]["properties"]["heartbeat_rate"] == {"type": "number", "minimum": 0.1, "maximum": 1e4}
    assert talker["schema"]["properties"]["visualization"] == {"type": "boolean"}

    # A viewer changes nothing: 403 naming its role, and the component is as it was.
    for path, body in (("/api/v1/settings/talker", {"values": {"heartbeat_rate": 4.0}}), ("/api/v1/components/talker/stop", {}),
                       ("/api/v1/components/talker/restart", {})):
        status, answer, _ = request(secured, "POST", path, viewer, json_body=body)
        assert status == 403 and "may only watch" in answer and "viewer" in answer, (path, status, answer)
    assert _control(secured, "talker", "get_state")["state"] == "active"
    assert _control(secured, "talker", "info")["config"]["heartbeat_rate"] == before

    # An operator: wrong types, unknown and read-only parameters, 422 naming the parameter.
    wrong = [({"values": {"heartbeat_rate": "fast"}}, "body.values.heartbeat_rate", "expected a number"),
             ({"values": {"heartbeat_rate": 0.0}}, "body.values.heartbeat_rate", "must be >= 0.1"),
             ({"values": {"visualization": 1}}, "body.values.visualization", "expected a boolean"),
             ({"values": {"no_such_parameter": 1}}, "body.values.no_such_parameter", "unknown field"),
             ({"values": {}}, "body.values", "give at least 1"),
             ({"values": [1]}, "body.values", "expected an object"),
             ({"heartbeat_rate": 4.0}, "body.values", "required")]
    for body, field, words in wrong:
        status, answer, _ = request(secured, "POST", "/api/v1/settings/talker", operator, json_body=body)
        assert status == 422 and answer["field"] == field and words in answer["error"], (body, status, answer)
    assert _control(secured, "talker", "info")["config"]["heartbeat_rate"] == before  # nothing changed
    status, answer, _ = request(secured, "POST", "/api/v1/settings/nosuch", operator, json_body={"values": {"heartbeat_rate": 4.0}})
    assert status == 404 and "'nosuch'" in answer["error"] and answer["field"] == "component", answer

    # ... and a right one: applied in the component's process, all of it.
    status, answer, _ = request(secured, "POST", "/api/v1/settings/talker", operator, json_body={"values": {"heartbeat_rate": 4.0}})
    assert status == 200 and answer["ok"] and answer["values"]["heartbeat_rate"] == 4.0, answer
    assert _control(secured, "talker", "info")["config"]["heartbeat_rate"] == 4.0
    status, answer, _ = request(secured, "POST", "/api/v1/settings/talker", operator, json_body={"values": {"heartbeat_rate": before}})
    assert status == 200, answer

    # Stop and start: the lifecycle's deactivate and activate, seen on the component itself.
    status, answer, _ = request(secured, "POST", "/api/v1/components/talker/stop", operator, json_body={})
    assert status == 200 and answer["ok"], answer
    wait_until(lambda: _control(secured, "talker", "get_state")["state"] != "active", what="the talker stopped")
    status, answer, _ = request(secured, "POST", "/api/v1/components/talker/start", operator)
    assert status == 200 and answer["ok"], answer
    wait_until(lambda: _control(secured, "talker", "get_state")["state"] == "active", what="the talker active again")
    for path, code, words in (("/api/v1/components/nosuch/stop", 404, "'nosuch'"), ("/api/v1/components/talker/explode", 404, "'explode'"),
                              ("/api/v1/components/ui/stop", 409, "cannot stop itself")):
        status, answer, _ = request(secured, "POST", path, operator, json_body={})
        assert status == code and words in answer["error"], (path, status, answer)

    # The document has them, with each component's schema.
    status, doc, _ = request(secured, "GET", "/api/v1/openapi.json", viewer)
    assert status == 200
    for path in ("/api/v1/settings", "/api/v1/settings/{component}", "/api/v1/components/{component}/start",
                 "/api/v1/components/{component}/stop", "/api/v1/components/{component}/restart"):
        assert path in doc["paths"], path
    assert doc["components"]["schemas"]["settings_talker"]["properties"]["heartbeat_rate"]["minimum"] == 0.1

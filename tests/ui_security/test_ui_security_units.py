"""Issue 41 item 2, the parts on their own: the device-token store, the attempt limiter, the
request checker's field names, pairing codes, and the definition-time refusals of enable_ui."""
from __future__ import annotations

import hashlib
import json
import os

import pytest

from emos.actors.ui.devices import DeviceStore, DeviceStoreError
from emos.actors.ui.openapi import RequestInvalid, check, envelope, input_schema, message_schema
from emos.actors.ui.pairing import ALPHABET, AttemptLimiter, new_code, normalize, same_code

pytestmark = pytest.mark.unit


class Clock:
    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_device_tokens_are_hashed_expire_and_are_revoked(tmp_path):
    run = tmp_path / "run"
    run.mkdir(mode=0o700)
    clock = Clock()
    store = DeviceStore(run / "ui.devices.json", clock=clock)
    token, record = store.issue("tablet", "operator", ttl_s=60.0)
    assert token.startswith("emosd_") and record["status"] == "active" and "sha256" not in record
    text = (run / "ui.devices.json").read_text()
    secret = token.split(".", 1)[1]
    assert secret not in text and hashlib.sha256(secret.encode()).hexdigest() in text
    assert oct(os.stat(run / "ui.devices.json").st_mode & 0o777) == "0o600"
    assert store.check(token)[0]["role"] == "operator"
    assert store.check(token[:-1] + ("A" if token[-1] != "A" else "B")) == (None, "unknown device token")
    assert store.check("not-a-token")[1] == "not a device token"
    viewer, _ = store.issue("wall", "viewer", ttl_s=600.0)
    clock.t += 61
    assert "has expired" in store.check(token)[1] and store.check(viewer)[0]["role"] == "viewer"
    assert [r["id"] for r in store.revoke("wall")] and "was revoked" in store.check(viewer)[1]
    assert store.revoke("wall") == []
    assert {r["name"]: r["status"] for r in store.listing()} == {"tablet": "expired", "wall": "revoked"}
    clock.t += 2 * 86400  # dead records are dropped a day later, at the next write
    store.issue("phone", "viewer", ttl_s=60.0)
    assert [r["name"] for r in store.listing()] == ["phone"]
    with pytest.raises(ValueError, match="role must be one of viewer, operator"):
        store.issue("x", "admin", ttl_s=60.0)
    with pytest.raises(ValueError, match="device name"):
        store.issue("<script>", "viewer", ttl_s=60.0)


def test_a_store_that_is_not_private_is_not_used(tmp_path):
    run = tmp_path / "run"
    run.mkdir(mode=0o700)
    path = run / "ui.devices.json"
    store = DeviceStore(path)
    token, _ = store.issue("tablet", "operator", ttl_s=60.0)
    path.chmod(0o644)  # someone else could have written a record of theirs
    record, why = store.check(token)
    assert record is None and "not a file of ours with mode 0600" in why
    shared = tmp_path / "shared"
    shared.mkdir(mode=0o755)
    shared.chmod(0o755)
    with pytest.raises(DeviceStoreError, match="has mode 0o755, not 0o700"):
        DeviceStore(shared / "ui.devices.json").issue("x", "viewer", ttl_s=1.0)
    path.chmod(0o600)
    path.write_text("{not json")
    assert "not valid" in store.check(token)[1]
    path.write_text(json.dumps({"devices": [{"id": "x"}]}))
    assert store.check(token)[1] == "unknown device token"


def test_the_attempt_limiter_blocks_a_client_then_everyone():
    clock = Clock()
    limiter = AttemptLimiter(3, window=60.0, clock=clock)
    for _ in range(3):
        assert limiter.blocked("a") == 0
        limiter.failed("a")
    assert limiter.blocked("a") == pytest.approx(60.0) and limiter.blocked("b") == 0
    clock.t += 30
    assert limiter.blocked("a") == pytest.approx(30.0)
    clock.t += 31
    assert limiter.blocked("a") == 0  # the window passed
    for i in range(30):  # 10 x per_client from many clients: everyone waits
        limiter.failed(f"c{i}")
    assert limiter.blocked("fresh") > 0


def test_pairing_codes():
    codes = {new_code() for _ in range(200)}
    assert len(codes) == 200 and all(len(c) == 9 and c[4] == "-" and set(c.replace("-", "")) <= set(ALPHABET) for c in codes)
    code = new_code()
    assert same_code(code.lower().replace("-", " "), code) and normalize(" ab-cd ") == "ABCD"
    assert not same_code("", code) and not same_code(None, code) and not same_code(code, "")


def test_the_checker_names_the_field():
    from emos.msgs.registry import resolve

    twist = envelope("value", message_schema(resolve("Twist")))
    check(twist, {"value": {"linear": {"x": 1, "y": 2.5}}})
    cases = [({"value": {"linear": {"x": "1"}}}, "body.value.linear.x", "expected a number, got string '1'"),
             ({"value": {"linear": {"x": True}}}, "body.value.linear.x", "expected a number, got boolean True"),
             ({"value": {"linear": {"x": float("nan")}}}, "body.value.linear.x", "finite"),
             ({"value": {"spin": {}}}, "body.value.spin", "unknown field"),
             ({}, "body.value", "required"), ([], "body", "expected an object")]
    for body, field, words in cases:
        with pytest.raises(RequestInvalid) as err:
            check(twist, body)
        assert err.value.field == field and words in str(err.value), (body, str(err.value))
    with pytest.raises(RequestInvalid, match=r"body.value: must be <= 255, got 300"):
        check(envelope("value", input_schema("UInt8")), {"value": 300})
    check(envelope("value", input_schema("UInt8")), {"value": 7.0})  # a whole number is an integer in JSON


def test_enable_ui_refuses_plain_http_off_loopback_and_half_certificates(tmp_path, monkeypatch):
    from emos import Launcher, Topic

    for env in ("EMOS_UI_TLS", "EMOS_UI_CERTFILE", "EMOS_UI_KEYFILE", "EMOS_UI_KEYSTORE", "EMOS_UI_HOST"):
        monkeypatch.delenv(env, raising=False)
    text = Topic(name="q", msg_type="String")
    launcher = Launcher()
    with pytest.raises(ValueError, match="off loopback the UI needs HTTPS"):
        launcher.enable_ui(outputs=[text], host="0.0.0.0", tls="off")
    with pytest.raises(ValueError, match="give both certfile and keyfile"):
        launcher.enable_ui(outputs=[text], certfile=str(tmp_path / "x.crt"))
    with pytest.raises(ValueError, match="is not a file"):
        launcher.enable_ui(outputs=[text], certfile=str(tmp_path / "x.crt"), keyfile=str(tmp_path / "x.key"))
    with pytest.raises(ValueError, match="UIConfig.tls must be one of"):
        launcher.enable_ui(outputs=[text], tls="sometimes")
    launcher.enable_ui(outputs=[text], host="0.0.0.0")  # HTTPS by default off loopback
    config = launcher._ui["config"]
    assert config.uses_tls() and len(normalize(config.pairing_code)) == 8 and config.pairing_code not in repr(config)
    launcher.enable_ui(outputs=[text])
    assert not launcher._ui["config"].uses_tls()  # loopback: plain HTTP unless asked
    monkeypatch.setenv("EMOS_UI_TLS", "on")  # `emos run --ui-https`
    launcher.enable_ui(outputs=[text])
    assert launcher._ui["config"].uses_tls()

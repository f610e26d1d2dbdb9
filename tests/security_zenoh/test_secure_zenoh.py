"""Zenoh with the keystore's mutual TLS and the access rules derived from a real recipe
(recipes/point_navigation.py): real sessions, real TLS, real certificates made by
emos.security.keystore, EMOS's own Zenoh publishers and subscribers, free ports.

Who cannot join: a peer with no certificate, with a certificate of another CA, with an expired
one, over plain TCP. Who joins but may not publish /cmd_vel (an operator: /cmd_vel is the
DriveManager's output): its messages never reach the robot's subscriber while its permitted
input (/initialpose) does, and the robot's security watch logs the attempt, once per interval."""
import datetime
import json
import logging
import socket
import time

import pytest

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

from emos.msgs import Twist  # noqa: E402
from emos.security.keystore import create_identity, create_keystore, load_identity  # noqa: E402
from emos.security.policy import Roles, write_policies  # noqa: E402
from emos.security.recipe_graph import load_recipe_graph  # noqa: E402
from emos.security.watch import SecurityWatch  # noqa: E402
from emos.transport import zenoh_net  # noqa: E402
from emos.transport.zenoh_net import ZenohPublisher, ZenohSubscriber  # noqa: E402

RECIPE = "recipes/point_navigation.py"
GROUP = "sectest"
WAIT = 20.0  # bounds a hang only


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(cond, timeout=WAIT, step=0.05):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(step)
    return cond()


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("sec")
    ks, other = root / "keys", root / "other-keys"
    create_keystore(ks)
    create_keystore(other)
    local = ["127.0.0.1", "localhost"]
    for name in ("robot1", "alice", "bob"):
        create_identity(ks, name, hosts=local)
    create_identity(other, "alice", hosts=local)  # same name, another CA
    past = datetime.datetime.now(datetime.UTC) - datetime.timedelta(days=30)
    create_identity(ks, "stale", hosts=local, valid_from=past, days=2)
    graph = load_recipe_graph(RECIPE)
    port = _free_port()
    roles = Roles(robots=["robot1"], operators=["alice"], viewers=["bob"])
    files = write_policies(graph, roles, ks, GROUP, root / "policies", listen=[f"tls/127.0.0.1:{port}"],
                           connect=[f"tls/127.0.0.1:{port}"])
    by_name = {p.stem: p for p in files}
    # the robot's own file: listen only (connecting to itself is only for its other processes)
    robot_conf = json.loads("\n".join(line for line in by_name["robot1"].read_text().splitlines() if not line.startswith("//")))
    robot_conf["connect"]["endpoints"] = []
    by_name["robot1"].write_text(json.dumps(robot_conf))
    yield {"root": root, "ks": ks, "other": other, "graph": graph, "files": by_name, "port": port, "robot_conf": robot_conf}
    zenoh_net.close_sessions()


def _variant(world, name, tls_changes=None, endpoint=None, tag=""):
    """A copy of operator alice's file with another certificate / endpoint."""
    conf = json.loads(json.dumps(world["robot_conf"]))
    conf["listen"]["endpoints"] = []
    conf["connect"]["endpoints"] = [endpoint or f"tls/127.0.0.1:{world['port']}"]
    tls = conf["transport"]["link"]["tls"]
    for key, value in (tls_changes or {}).items():
        if value is None:
            tls.pop(key, None)
        else:
            tls[key] = value
    if endpoint and endpoint.startswith("tcp/"):
        conf["transport"]["link"]["protocols"] = ["tcp"]
    path = world["root"] / f"{name}{tag}.json5"
    path.write_text(json.dumps(conf))
    return str(path)


@pytest.fixture(scope="module")
def robot(world):
    path = str(world["files"]["robot1"])
    got = {"/cmd_vel": [], "/initialpose": []}
    subs = {t: ZenohSubscriber(t, Twist, notify=None, queue_size=1000, config_path=path, group=GROUP) for t in got}
    sess = zenoh_net.session(path)
    yield {"path": path, "subs": subs, "session": sess}
    for s in subs.values():
        s.close()


def _twist(x):
    msg = Twist()
    msg.linear.x = x
    return msg


def _drain(sub):
    return [m.linear.x for m in sub.take()]


def _peer_cn(sess):
    """The certificate common names of the robot session's links (Zenoh's admin space)."""
    me = sess.info.zid()
    names = []
    for reply in sess.get(f"@/{me}/session/transport/unicast/*/link/*", timeout=2.0):
        if reply.ok is not None:
            names.append(json.loads(reply.ok.payload.to_bytes()).get("auth_identifier"))
    return names


def _intruder_config(world, case):
    ks, other = world["ks"], world["other"]
    if case == "no certificate":
        changes = {"connect_certificate": None, "connect_private_key": None, "listen_certificate": None, "listen_private_key": None}
        return _variant(world, "nocert", changes)
    if case == "another CA":  # a certificate named like an allowed identity, from another CA
        cert, key, ca = load_identity(other, "alice")
        return _variant(world, "foreign", {"connect_certificate": str(cert), "connect_private_key": str(key), "root_ca_certificate": str(ca),
                                           "listen_certificate": str(cert), "listen_private_key": str(key)})
    if case == "expired certificate":
        cert, key, _ = load_identity(ks, "stale", allow_expired=True)
        return _variant(world, "stale", {"connect_certificate": str(cert), "connect_private_key": str(key),
                                         "listen_certificate": str(cert), "listen_private_key": str(key)})
    return _variant(world, "tcp", {}, endpoint=f"tcp/127.0.0.1:{world['port']}")


INTRUDERS = ["no certificate", "another CA", "expired certificate", "plain TCP"]


def test_a_peer_without_a_valid_certificate_cannot_join(world, robot):
    """All four at once, publishing on a topic an operator may publish, for a few seconds (a
    valid identity joins in about one): none gets a link, nothing of theirs arrives."""
    intruders = {case: zenoh.open(zenoh.Config.from_file(_intruder_config(world, case))) for case in INTRUDERS}
    try:
        pubs = {case: sess.declare_publisher(f"emos/{GROUP}/initialpose") for case, sess in intruders.items()}
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            for pub in pubs.values():
                pub.put(b"x" * 64)
            time.sleep(0.1)
        linked = [case for case, sess in intruders.items() if list(sess.info.peers_zid())]
        assert linked == [], f"intruders with a link to the robot: {linked}"
        assert _drain(robot["subs"]["/initialpose"]) == []
        assert robot["subs"]["/initialpose"].rejected == 0  # not even a foreign frame came through
        assert [cn for cn in _peer_cn(robot["session"]) if cn not in ("alice", "bob")] == []
    finally:
        for sess in intruders.values():
            sess.close()


def test_a_valid_identity_publishes_what_it_may_and_nothing_else(world, robot, caplog):
    """alice (operator) may publish /initialpose (an external input of the recipe), not /cmd_vel
    (the DriveManager's output): only /initialpose arrives; the robot's watch logs /cmd_vel once."""
    acl = world["robot_conf"]["access_control"]
    watch = SecurityWatch(robot["session"], acl, GROUP, interval=60.0)
    alice = str(world["files"]["alice"])
    caplog.set_level(logging.WARNING, logger="emos.security")
    pubs: list[ZenohPublisher] = []
    try:
        cmd = ZenohPublisher("/cmd_vel", Twist, publisher_id="teleop", config_path=alice, group=GROUP)
        pubs.append(cmd)
        pose = ZenohPublisher("/initialpose", Twist, publisher_id="operator", config_path=alice, group=GROUP)
        pubs.append(pose)
        pubs.append(ZenohPublisher("/cmd_vel", Twist, publisher_id="teleop2", config_path=alice, group=GROUP))
        assert _wait(lambda: "alice" in _peer_cn(robot["session"])), "alice (valid certificate) never joined"
        received: list[float] = []
        deadline, i = time.monotonic() + WAIT, 0  # until the routes are up (slow on a busy machine), then 20 messages
        while len(received) < 20 and time.monotonic() < deadline:
            cmd.publish(_twist(100.0 + i))
            pose.publish(_twist(float(i)))
            received += _drain(robot["subs"]["/initialpose"])
            i += 1
            time.sleep(0.02)
        assert received, "the permitted topic never arrived"
        # Keep publishing on /cmd_vel for a while longer after the permitted topic flows.
        for i in range(20):
            cmd.publish(_twist(500.0 + i))
            time.sleep(0.01)
        time.sleep(0.5)
        assert _drain(robot["subs"]["/cmd_vel"]) == [], "a message of an identity without permission reached the subscriber"
        assert robot["subs"]["/cmd_vel"].rejected == 0
        # the attempt is logged, naming the identity and the topic; the second publisher is
        # counted but does not add a line (rate-limited per identity and topic)
        assert _wait(lambda: watch.denied_seen >= 2), "the watch never saw alice's publishers on /cmd_vel"
        lines = [r.getMessage() for r in caplog.records if r.name == "emos.security"]
        denied = [line for line in lines if "'alice'" in line and "/cmd_vel" in line]
        assert len(denied) == 1, lines
        assert not any("/initialpose" in line for line in lines), lines
    finally:
        for p in pubs:  # on every path: a failed test must not leave its routes to the next
            p.close()
        watch.close()


def test_latched_topics_and_services_follow_the_roles(world, robot):
    """A latched /map published by the robot before anyone joined reaches the operator and the
    viewer (zenoh.ext's cache keys are in their rules); the planner's service answers the
    operator and not the viewer."""
    path = robot["path"]
    pub = ZenohPublisher("/map", Twist, publisher_id="global_map_server", config_path=path, group=GROUP, transient_local=True, depth=1)
    pub.publish(_twist(42.0))
    queryable = robot["session"].declare_queryable(f"emos/{GROUP}/_srv_/planner/service", lambda q: q.reply(q.key_expr, b"pong"))
    try:
        for who, may_call in (("alice", True), ("bob", False)):
            conf = str(world["files"][who])
            sub = ZenohSubscriber("/map", Twist, notify=None, queue_size=5, config_path=conf, group=GROUP, transient_local=True)
            got = []
            assert _wait(lambda got=got, sub=sub: got.extend(_drain(sub)) or got), f"{who} never received the latched /map"
            assert got == [42.0]
            sub.close()
            sess = zenoh_net.session(conf)
            replies = [r.ok.payload.to_bytes() for r in sess.get(f"emos/{GROUP}/_srv_/planner/service", timeout=3.0) if r.ok is not None]
            assert replies == ([b"pong"] if may_call else []), who
    finally:
        queryable.undeclare()
        pub.close()

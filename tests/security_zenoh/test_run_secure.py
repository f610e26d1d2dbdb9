"""``emos security`` and ``emos run --secure`` end to end, through the CLI: a keystore and two
identities, the policy of a recipe, a multi-process run on it, and an operator (alice) on its own
Zenoh session: what the recipe lets her publish (/goal, an input no component publishes) reaches
the component; /cmd_vel (the Driver's output) never does, and the run's security watch logs her
attempt. The service the listener creates when it configures (listener/ping) is in the derived
policy, so the robot may serve it over the network and alice may call it. A run given a plain configuration with --secure refuses to start."""
import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

RECIPE = """
import json, os
from emos import BaseComponent, Launcher, Topic
from emos.msgs import TriggerRequest, TriggerResponse, Twist

OUT = os.environ.get("SEC_OUT", "seen.json")

class Listener(BaseComponent):
    def custom_on_configure(self):
        self.create_service(f"{self.component_name}/ping", TriggerRequest, TriggerResponse, self._ping)
    def _ping(self, request):
        return TriggerResponse(success=True, message="pong from " + self.component_name)
    def custom_on_activate(self):
        self.seen = {"goal": [], "cmd_vel": []}
    def _execution_step(self):
        changed = False
        for name in ("goal", "cmd_vel"):
            msg = self.get_input("/" + name)
            if msg is not None and msg.linear.x not in self.seen[name]:
                self.seen[name].append(msg.linear.x)
                changed = True
        if changed:
            with open(OUT + ".tmp", "w") as f:
                json.dump(self.seen, f)
            os.replace(OUT + ".tmp", OUT)
        self.health_status.set_healthy()

class Driver(BaseComponent):
    def _execution_step(self):
        msg = Twist()
        msg.linear.x = -1.0
        self.publish(self.out_topics[0], msg)
        self.health_status.set_healthy()

goal = Topic(name="goal", msg_type="Twist", transport="zenoh")
cmd = Topic(name="cmd_vel", msg_type="Twist", transport="zenoh")
listener = Listener(component_name="listener", inputs=[goal, cmd])
listener.config.loop_rate = 50.0
driver = Driver(component_name="driver", outputs=[cmd])
driver.config.loop_rate = 2.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[listener, driver])
launcher.bringup()
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _emos(*args, env=None, check=True):
    proc = subprocess.run([sys.executable, "-m", "emos.tools.cli", *args], capture_output=True, text=True, timeout=120, env=env)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


def _seen(path):
    try:
        return json.loads(open(path).read())
    except (FileNotFoundError, ValueError):
        return {"goal": [], "cmd_vel": []}


def test_secure_run_enforces_the_recipe_policy(tmp_path, monkeypatch):
    from emos.msgs import TriggerRequest, TriggerResponse, Twist
    from emos.transport import zenoh_net
    from emos.transport.zenoh_rpc import NetServiceClient, ServiceUnavailable

    ks, recipe, out = tmp_path / "keys", tmp_path / "secure_recipe.py", tmp_path / "seen.json"
    recipe.write_text(RECIPE)
    _emos("security", "create-keystore", str(ks))
    again = _emos("security", "create-keystore", str(ks), check=False)
    assert again.returncode == 2 and "refusing to overwrite" in again.stderr
    _emos("security", "create-identity", str(ks), "robot1")
    _emos("security", "create-identity", str(ks), "alice")
    port = _free_port()
    group = f"sec{os.getpid()}"
    _emos("security", "policy", str(recipe), "--keystore", str(ks), "--identity", "robot1", "--operator", "alice",
          "--group", group, "--listen", f"tls/127.0.0.1:{port}", "--connect", f"tls/127.0.0.1:{port}")
    alice_conf = str(ks / "policies" / "secure_recipe" / "alice.json5")
    with open(alice_conf) as f:
        assert f"emos/{group}/_srv_/listener/ping" in f.read()  # created at configure time, derived all the same
    env = dict(os.environ, SEC_OUT=str(out), EMOS_NET_GROUP=group, PYTHONUNBUFFERED="1", EMOS_NET_SERVICES="all")
    monkeypatch.setenv("EMOS_NET_GROUP", group)  # the service client's key
    log_path = tmp_path / "run.log"
    with open(log_path, "w") as log:
        run = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "run", "--no-log", "--secure", str(ks), "--duration", "120", str(recipe)],
                               stdout=log, stderr=subprocess.STDOUT, env=env, cwd=tmp_path, start_new_session=True)
    pubs = []
    try:
        goal = zenoh_net.ZenohPublisher("/goal", Twist, publisher_id="alice-goal", config_path=alice_conf, group=group)
        cmd = zenoh_net.ZenohPublisher("/cmd_vel", Twist, publisher_id="alice-teleop", config_path=alice_conf, group=group)
        pubs = [goal, cmd]
        deadline = time.monotonic() + 90.0  # bounds a hang only
        i = 0
        while time.monotonic() < deadline and (len(_seen(out)["goal"]) < 5 or -1.0 not in _seen(out)["cmd_vel"]):
            for pub, base in ((goal, 0.0), (cmd, 1000.0)):
                msg = Twist()
                msg.linear.x = base + i
                pub.publish(msg)
            i += 1
            time.sleep(0.05)
            assert run.poll() is None, log_path.read_text()[-3000:]
        seen = _seen(out)
        assert len(seen["goal"]) >= 5, f"alice's permitted /goal never reached the component: {log_path.read_text()[-3000:]}"
        assert all(x < 1000.0 for x in seen["cmd_vel"]), f"alice's /cmd_vel reached the component: {seen}"
        assert -1.0 in seen["cmd_vel"], f"the run's own /cmd_vel never arrived: {log_path.read_text()[-3000:]}"
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and "identity 'alice'" not in log_path.read_text():
            time.sleep(0.2)
        text = log_path.read_text()
        warned = [line for line in text.splitlines() if "identity 'alice'" in line]
        assert warned and all("/cmd_vel" in line for line in warned), text[-3000:]
        assert "secure Zenoh (mutual TLS, access rules)" in text
        # The configure-time service: served by the robot and called by alice, through the rules.
        ping = NetServiceClient("/listener/ping", TriggerRequest, TriggerResponse, config_path=alice_conf)
        answer, deadline = None, time.monotonic() + 60.0  # bounds a hang only
        while answer is None and time.monotonic() < deadline:
            try:
                answer = ping.call(TriggerRequest(), timeout=3.0)
            except ServiceUnavailable:
                assert run.poll() is None, log_path.read_text()[-3000:]
        assert answer is not None and answer.success and answer.message == "pong from listener", log_path.read_text()[-3000:]
    finally:
        for p in pubs:
            p.close()
        zenoh_net.close_sessions()
        if run.poll() is None:
            os.kill(run.pid, signal.SIGINT)  # as `kill -INT`: the run stops its components and its watch
        try:
            run.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(run.pid, signal.SIGKILL)
            run.wait()
    leftovers = subprocess.run(["pgrep", "-f", "emos.security.watch"], capture_output=True, text=True).stdout.split()
    assert not [pid for pid in leftovers if _parent_is_gone_child_of(pid, run.pid)], "the security watch outlived its run"


def _parent_is_gone_child_of(pid: str, run_pid: int) -> bool:
    """Whether process ``pid`` belongs to the stopped run's session (its process group)."""
    try:
        return os.getpgid(int(pid)) == run_pid
    except ProcessLookupError:
        return False


def test_secure_run_refuses_a_plain_configuration(tmp_path):
    ks = tmp_path / "keys"
    _emos("security", "create-keystore", str(ks))
    plain = tmp_path / "plain.json5"
    plain.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": ["tcp/127.0.0.1:0"]}}))
    recipe = tmp_path / "r.py"
    recipe.write_text("raise SystemExit('the recipe must not run')\n")
    proc = _emos("run", "--no-log", "--secure", str(ks), "--zenoh", str(plain), str(recipe), check=False)
    assert proc.returncode == 2 and "is not secure" in proc.stderr and "enable_mtls" in proc.stderr
    proc = _emos("run", "--no-log", "--secure", str(ks), str(recipe), check=False)
    assert proc.returncode == 2 and "emos security policy" in proc.stderr

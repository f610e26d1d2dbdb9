"""The robot plugin API on a toy device over real UDP and TCP sockets: decoders publish,
encoders write, the command watchdog fires once per silence, heartbeats go out, a lost link is
a SYSTEM_FAILURE naming the device and comes back; declarations are checked at definition."""
from __future__ import annotations

import socket
import threading
import time
from collections.abc import Mapping
from typing import ClassVar

import pytest
from attrs import define, field

from emos.actors.hardware.plugin import (
    Command,
    Feedback,
    Heartbeat,
    PluginConfig,
    PluginEvent,
    RobotPlugin,
    TcpTransport,
    UdpTransport,
    plugin_action,
)
from emos.config import validators as V
from emos.msgs.std import Float32, String
from emos.testing import ComponentHarness

pytestmark = pytest.mark.process  # real sockets and reader threads


@define(kw_only=True)
class ToyConfig(PluginConfig):
    loop_rate: float = field(default=50.0, validator=V.finite_positive)
    host: str = field(default="127.0.0.1", validator=V.non_empty_str)
    port: int = field(default=9, validator=V.number(gt=0, lt=65536, integer=True))
    kind: str = field(default="udp", validator=V.in_(("udp", "tcp")))
    cmd_timeout: float = field(default=0.5, validator=V.finite_positive)


class ToyBot(RobotPlugin):
    """A line protocol: the device sends ``V <volts>\\n``; we send ``SAY <text>\\n``, ``STOP\\n``
    when commands go quiet, and ``PING\\n`` every 0.2 s."""

    plugin_name = "toy"
    feedback: ClassVar[Mapping[str, Feedback]] = {"volts": Feedback(msg_type="Float32", topic="/toy/volts")}
    commands: ClassVar[Mapping[str, Command]] = {"say": Command(msg_types=("String",), topic="/toy/say", timeout="cmd_timeout")}
    plugin_events: ClassVar[Mapping[str, PluginEvent]] = {"low": PluginEvent(feedback="volts", condition=lambda t: t.msg.data < 11.0, when="volts < 11")}

    def __init__(self, component_name: str = "toy", config: ToyConfig | None = None, **kw) -> None:
        super().__init__(component_name, config or ToyConfig(), **kw)
        self.buf, self.timeouts = b"", 0

    @classmethod
    def config_class(cls):
        return ToyConfig

    def make_transports(self):
        cfg = self.config
        cls = UdpTransport if cfg.kind == "udp" else TcpTransport
        return {"link": cls("toy device", cfg.host, cfg.port)}

    def heartbeats(self):
        return [Heartbeat(transport="link", period=0.2, payload=b"PING\n")]

    def on_data(self, name, data):
        self.buf += data
        *lines, self.buf = self.buf.split(b"\n")
        for line in lines:
            if line.startswith(b"V "):
                self.emit("volts", Float32(data=float(line[2:])))

    def on_command(self, key, msg):
        self.send("link", b"SAY " + msg.data.encode() + b"\n")

    def on_command_timeout(self, key):
        self.timeouts += 1
        self.send("link", b"STOP\n")

    @plugin_action("say hello at once")
    def hello(self) -> bool:
        return self.send("link", b"SAY hello\n") is not None


class UdpDevice:
    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.got: list[bytes] = []
        self.peer = None
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set():
            try:
                data, self.peer = self.sock.recvfrom(4096)
            except (TimeoutError, OSError):
                continue
            self.got.append(data)

    def say(self, data: bytes):
        self.sock.sendto(data, self.peer)

    def close(self):
        self._stop.set()
        self.thread.join(2)
        self.sock.close()


def _until(h, cond, timeout=20.0):
    end = time.monotonic() + timeout  # bounds a hang only
    while not cond():
        if time.monotonic() > end:
            raise TimeoutError("condition never held")
        h.advance(h.tick)
        time.sleep(0.005)


def test_udp_plugin_decodes_encodes_beats_and_its_watchdog_fires_once_per_silence():
    dev = UdpDevice()
    try:
        with ComponentHarness(ToyBot(config=ToyConfig(port=dev.port))) as h:
            comp = h.component
            _until(h, lambda: b"PING\n" in dev.got)  # the heartbeat reaches the device
            h.feed("/toy/say", String(data="hi"))
            _until(h, lambda: b"SAY hi\n" in dev.got)
            dev.say(b"V 12.5\nV 10.")  # a line split across datagrams
            dev.say(b"5\n")
            _until(h, lambda: h.latest("/toy/volts") is not None and h.latest("/toy/volts").data == 10.5)
            assert h.health.is_healthy
            stops_before = dev.got.count(b"STOP\n")
            h.advance(1.5)  # silence on /toy/say: one STOP, not one per poll
            _until(h, lambda: dev.got.count(b"STOP\n") > stops_before)
            h.advance(1.0)
            time.sleep(0.1)
            assert dev.got.count(b"STOP\n") == stops_before + 1
            h.feed("/toy/say", String(data="again"))  # a fresh command re-arms the watchdog
            h.advance(1.0)
            _until(h, lambda: dev.got.count(b"STOP\n") == stops_before + 2)
            assert comp.hello() and comp.plugin_actions == {"hello": "say hello at once"}
    finally:
        dev.close()


class TcpDevice:
    """A TCP device that can be unplugged (listener and connections closed) and plugged back."""

    def __init__(self):
        self.port, self.conns = 0, []
        self.plug()

    def plug(self):
        self.server = socket.create_server(("127.0.0.1", self.port))  # SO_REUSEADDR: the same port again
        self.port = self.server.getsockname()[1]
        self.server.settimeout(0.05)
        self.up = threading.Event()
        self.up.set()
        self.thread = threading.Thread(target=self._accept, args=(self.server,), daemon=True)
        self.thread.start()

    def _accept(self, server):
        while self.up.is_set():
            try:
                self.conns.append(server.accept()[0])
            except (TimeoutError, OSError):
                continue

    def unplug(self):
        self.up.clear()
        self.thread.join(2)
        self.server.close()
        for c in self.conns:
            c.close()


def test_tcp_device_gone_is_system_failure_naming_it_and_the_ladder_reconnects():
    dev = TcpDevice()
    try:
        with ComponentHarness(ToyBot(config=ToyConfig(port=dev.port, kind="tcp"))) as h:
            _until(h, lambda: len(dev.conns) == 1)
            dev.conns[0].sendall(b"V 12.0\n")
            _until(h, lambda: h.latest("/toy/volts") is not None)
            dev.unplug()  # the device goes away
            _until(h, lambda: h.health.is_system_fail)
            message = h.component.health_status().message
            assert f"tcp://127.0.0.1:{dev.port}" in message and "toy device" in message
            h.advance(1.0)
            assert h.health.is_system_fail  # still down: the ladder keeps trying
            dev.plug()
            _until(h, lambda: len(dev.conns) == 2)  # the ladder reconnected
            dev.conns[1].sendall(b"V 11.5\n")
            _until(h, lambda: h.latest("/toy/volts").data == 11.5 and h.health.is_healthy)
    finally:
        dev.unplug()


def test_unreachable_tcp_device_fails_activation_naming_it():
    probe = socket.create_server(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nothing listens there now
    comp = ToyBot(config=ToyConfig(port=port, kind="tcp"))
    with ComponentHarness(comp, activate=False) as h:
        with pytest.raises(Exception, match=f"toy device tcp://127.0.0.1:{port} cannot be reached"):
            h.activate()
        assert comp.health_status.is_system_fail and str(port) in comp.health_status().message

"""System-level measurements of ``emos bench agents``: real component processes against real
``emos serve models`` processes, fed and read through the topics like any other node.

* LLM overhead: question published -> LLM component -> answer received, against the same
  request sent straight to the same server by a client in this process (same run, same load).
* Vision throughput: 640x480 frames at 30 Hz into the Vision component with the on-board
  detector: frames answered per second, p95 frame-to-detections latency, frames dropped (the
  component keeps only the newest frame while busy, so the backlog never grows).
* Hot swap: the primary model server is SIGKILLed and a question published at once; the time
  until the backup's answer arrives.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

READY = re.compile(r"ready http=([\d.]+):(\d+) resp=(\S+)")


class ModelServer:
    """``emos serve models`` in a child process."""

    def __init__(self, *args: str, port: int = 0, script: str | None = None, timeout: float = 60.0) -> None:
        cmd = [sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", str(port), *args]
        if script:
            cmd += ["--script", script]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     env={**os.environ, "HF_HUB_OFFLINE": "1"})
        found: list[re.Match] = []

        def pump() -> None:  # keep draining so the server never blocks on a full pipe
            assert self.proc.stdout is not None
            for line in self.proc.stdout:
                match = READY.search(line)
                if match and not found:
                    found.append(match)

        threading.Thread(target=pump, daemon=True).start()
        end = time.monotonic() + timeout
        while not found:
            if self.proc.poll() is not None or time.monotonic() > end:
                self.kill()
                raise RuntimeError("emos serve models did not start")
            time.sleep(0.02)
        self.port = int(found[0].group(2))

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()


class RunningRecipe:
    """A recipe under ``emos run`` in a child process, with topic access for this process."""

    def __init__(self, source: str, components: list[str], timeout: float = 120.0) -> None:
        from emos.core.rpc import RpcClient
        from emos.transport.context import RunContext, runtime_root

        self._dir = tempfile.TemporaryDirectory(prefix="emos-bench-agents-")
        script = Path(self._dir.name) / "recipe.py"
        script.write_text(textwrap.dedent(source))
        self.proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(script)], cwd=self._dir.name,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self._subs: list[Any] = []
        self._pubs: list[Any] = []
        end = time.monotonic() + timeout
        run_dir = None
        while run_dir is None:
            if self.proc.poll() is not None or time.monotonic() > end:
                self.stop()
                raise RuntimeError("the benchmark recipe did not start")
            run_dir = next((d for d in runtime_root().iterdir()
                            if d.name.startswith(f"{self.proc.pid}-") and (d / "supervisor.sock").exists()), None)
            time.sleep(0.05)
        self.ctx = RunContext(run_dir.name, run_dir, owner=False)
        self.rpc = RpcClient(run_dir / "supervisor.sock")
        while not all(self._state(c) == "active" for c in components):
            if time.monotonic() > end:
                self.stop()
                raise RuntimeError(f"components {components} did not become active")
            time.sleep(0.1)

    def _state(self, name: str) -> str | None:
        from emos.supervisor.launched import component_states

        return component_states(self.rpc.call("tree")["tree"]).get(name)

    def publisher(self, topic: str, msg_type: type, depth: int = 10) -> Any:
        from emos.transport.pubsub import Publisher

        pub = Publisher(self.ctx, topic, msg_type, publisher_id="bench", depth=depth)
        self._pubs.append(pub)
        return pub

    def subscriber(self, topic: str, msg_type: type) -> Any:
        from emos.transport.pubsub import Subscriber

        sub = Subscriber(self.ctx, topic, msg_type, queue_size=1000)
        self._subs.append(sub)
        return sub

    def call_method(self, component: str, method: str, *args: Any) -> Any:
        from emos.core.control import ControlClient

        return ControlClient(component, self.ctx).execute_method(method, *args)

    def stop(self) -> None:
        for item in self._pubs + self._subs:
            item.close()
        if getattr(self, "rpc", None) is not None:
            self.rpc.close()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._dir.cleanup()


def _wait_one(sub: Any, timeout: float = 30.0) -> tuple[Any, float]:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got = sub.take()
        if got:
            return got[0], time.perf_counter()
        time.sleep(0.0002)
    raise TimeoutError("no answer within the timeout")


def _ms(samples: list[float]) -> dict[str, float]:
    arr = np.asarray(samples) * 1000.0
    return {"p50": round(float(np.percentile(arr, 50)), 3), "p95": round(float(np.percentile(arr, 95)), 3)}


def bench_llm_overhead(queries: int = 40) -> dict[str, Any]:
    from emos.actors.agents.clients import OllamaClient
    from emos.actors.agents.models import OllamaModel
    from emos.actors.agents.types import ChatMessage, ChatRequest
    from emos.msgs import String

    server = ModelServer()
    recipe = None
    try:
        recipe = RunningRecipe(f"""
            from emos import Launcher, Topic
            from emos.actors.agents import LLM, OllamaClient, OllamaModel
            q = Topic(name="bench_q", msg_type="String")
            a = Topic(name="bench_a", msg_type="String")
            llm = LLM(inputs=[q], outputs=[a], trigger=q, component_name="bench_llm",
                      model_client=OllamaClient(OllamaModel(name="m", checkpoint="emos-scripted"), port={server.port}))
            launcher = Launcher(multi_processing=True)
            launcher.add_pkg(components=[llm])
            launcher.bringup()
        """, ["bench_llm"])
        pub, sub = recipe.publisher("/bench_q", String), recipe.subscriber("/bench_a", String)
        client = OllamaClient(OllamaModel(name="m", checkpoint="emos-scripted"), port=server.port)
        through, direct = [], []
        for i in range(queries + 3):  # the first 3 warm up both paths
            text = f"question number {i}"
            start = time.perf_counter()
            pub.publish(String(data=text))
            msg, end = _wait_one(sub)
            assert msg.data == f"You said: {text}", msg.data
            start_direct = time.perf_counter()
            reply = client.chat(ChatRequest(messages=[ChatMessage(role="user", content=text)], temperature=0.8, max_tokens=500))
            end_direct = time.perf_counter()
            assert reply.message.content == f"You said: {text}"
            if i >= 3:
                through.append(end - start)
                direct.append(end_direct - start_direct)
        client.close()
        overhead = [t - d for t, d in zip(through, direct)]
        return {"overhead": _ms(overhead), "component": _ms(through), "direct": _ms(direct), "n": queries}
    finally:
        if recipe is not None:
            recipe.stop()
        server.stop()


_READY_S = 120.0  # bounds a component that never answers; a healthy one answers within seconds


def bench_vision(duration: float = 10.0, rate: float = 30.0) -> dict[str, Any]:
    from emos.msgs import Detections, Header, Image, Time

    recipe = RunningRecipe("""
        from emos import Launcher, Topic
        from emos.actors.agents import Vision, VisionConfig
        image = Topic(name="bench_image", msg_type="Image")
        dets = Topic(name="bench_detections", msg_type="Detections")
        vision = Vision(inputs=[image], outputs=[dets], trigger=image, component_name="bench_vision",
                        config=VisionConfig(enable_local_classifier=True))
        launcher = Launcher(multi_processing=True)
        launcher.add_pkg(components=[vision])
        launcher.bringup()
    """, ["bench_vision"])
    try:
        pub = recipe.publisher("/bench_image", Image, depth=4)
        sub = recipe.subscriber("/bench_detections", Detections)
        rng = np.random.default_rng(0)
        frames = [rng.integers(0, 255, (480, 640, 3), dtype=np.uint8) for _ in range(4)]
        # Measure from the first answer on: until then the component is loading its detector,
        # which takes as long as the machine makes it take (a fixed wait either wasted time or
        # measured the start-up on a busy machine).
        ready_by = time.monotonic() + _READY_S
        while not sub.take():
            if time.monotonic() > ready_by:
                raise RuntimeError(f"bench_vision answered no frame within {_READY_S:g} s")
            pub.publish(Image.from_numpy(frames[0], header=Header(stamp=Time.now())))
            time.sleep(0.2)
        time.sleep(0.2)  # the answers to the last warm-up frames, dropped below
        sub.take()
        latencies: list[float] = []
        answered = 0
        sent = 0
        start = time.monotonic()
        next_at = start
        while time.monotonic() - start < duration:
            now = time.monotonic()
            if now >= next_at:
                pub.publish(Image.from_numpy(frames[sent % 4], header=Header(stamp=Time.now())))
                sent += 1
                next_at += 1.0 / rate
            for msg in sub.take():
                answered += 1
                latencies.append(time.time() - msg.header.stamp.to_sec())
            time.sleep(0.001)
        drain_end = time.monotonic() + 2.0
        while time.monotonic() < drain_end and answered < sent:
            for msg in sub.take():
                answered += 1
                latencies.append(time.time() - msg.header.stamp.to_sec())
            time.sleep(0.005)
        return {"fps": round(answered / duration, 2), "p95_ms": _ms(latencies)["p95"] if latencies else None,
                "dropped": sent - answered, "sent": sent, "answered": answered}
    finally:
        recipe.stop()


def bench_hotswap(swaps: int = 5) -> dict[str, Any]:
    from emos.msgs import String

    backup = ModelServer()
    primary = ModelServer()
    port = primary.port
    recipe = None
    try:
        recipe = RunningRecipe(f"""
            from emos import Launcher, Topic
            from emos.actors.agents import LLM, OllamaClient, OllamaModel
            q = Topic(name="swap_q", msg_type="String")
            a = Topic(name="swap_a", msg_type="String")
            llm = LLM(inputs=[q], outputs=[a], trigger=q, component_name="swap_llm",
                      model_client=OllamaClient(OllamaModel(name="primary", checkpoint="emos-scripted"), port={port}))
            llm.additional_model_clients = {{"backup": OllamaClient(OllamaModel(name="backup", checkpoint="emos-scripted"),
                                                                     port={backup.port})}}
            launcher = Launcher(multi_processing=True)
            launcher.add_pkg(components=[llm])
            launcher.bringup()
        """, ["swap_llm"])
        pub, sub = recipe.publisher("/swap_q", String), recipe.subscriber("/swap_a", String)
        times = []
        for i in range(swaps):
            if i:  # a fresh primary on the same port, and the component back on it
                primary = _server_on(port)
                recipe.call_method("swap_llm", "change_model_client", "primary")
            pub.publish(String(data=f"warm {i}"))
            _wait_one(sub)
            primary.kill()
            start = time.perf_counter()
            pub.publish(String(data=f"swap {i}"))
            msg, end = _wait_one(sub)
            assert msg.data == f"You said: swap {i}", msg.data
            times.append(end - start)
        return _ms(times) | {"n": swaps}
    finally:
        if recipe is not None:
            recipe.stop()
        primary.kill()
        backup.stop()


def _server_on(port: int) -> ModelServer:
    """A new server on the port a killed one just left (retried briefly if it is not free yet)."""
    for _ in range(20):
        try:
            return ModelServer(port=port)
        except RuntimeError:
            time.sleep(0.2)
    raise RuntimeError(f"could not restart the primary model server on port {port}")

"""Chaos workload: an LLM whose primary model server drops, mid-request, while questions keep coming.

``llm`` answers ``questions`` through its primary client, which the chaos runner points at a
fault-injecting proxy in front of one model server (``EMOS_CHAOS_PROXY_MODEL``); its backup
client talks to a second server directly (``EMOS_CHAOS_SERVICE_BACKUP``). The proxy adds a
standing 150 ms latency, so a drop usually lands while a request is in flight. ``asker`` asks a
numbered question every second and checks each answer ("You said: q17", the local server's
scripted responder) against the question it answers, recording the time to answer. With
``EMOS_CHAOS_RESULT`` set it writes ``{"requests", "answered", "unanswered", "answer_ms"}``
there (``answer_ms``: ``[asked_at_wall_time, milliseconds]`` per answer), counting as unanswered
only questions older than 10 s when the run ends.
"""
import json
import os
import time

from emos import BaseComponent, Launcher, Topic
from emos.actors.agents import LLM, OllamaClient, OllamaModel
from emos.msgs import String


def _address(var, default):
    host, _, port = os.environ.get(var, default).rpartition(":")
    return host, int(port)


questions = Topic(name="questions", msg_type="String")
answers = Topic(name="answers", msg_type="String")

primary_host, primary_port = _address("EMOS_CHAOS_PROXY_MODEL", "127.0.0.1:8000")
backup_host, backup_port = _address("EMOS_CHAOS_SERVICE_BACKUP", "127.0.0.1:8001")
llm = LLM(inputs=[questions], outputs=[answers], trigger=questions, component_name="llm",
          model_client=OllamaClient(OllamaModel(name="primary", checkpoint="emos-scripted"),
                                    host=primary_host, port=primary_port, inference_timeout=5))
llm.additional_model_clients = {"backup": OllamaClient(OllamaModel(name="backup", checkpoint="emos-scripted"),
                                                       host=backup_host, port=backup_port, inference_timeout=5)}


class Asker(BaseComponent):
    """Asks ``q<n>`` every second and matches each answer to its question."""

    def custom_on_activate(self):
        self.sent = {}  # question -> wall time asked (wall time: it survives nothing, and needs not)
        self.answer_ms = []
        self.n = 0
        self.result_file = os.environ.get("EMOS_CHAOS_RESULT")
        self.create_timer(1.0, self.ask)

    def ask(self):
        question = f"q{self.n}"
        self.n += 1
        self.sent[question] = time.time()
        self.publish(questions, String(data=question))
        self._write()

    def _execution_step(self, msg=None, topic=None):
        if msg is not None:
            question = msg.data.rsplit(" ", 1)[-1]
            asked = self.sent.pop(question, None)
            if asked is not None:
                self.answer_ms.append([round(asked, 3), round((time.time() - asked) * 1e3, 1)])
            self._write()
        self.health_status.set_healthy()

    def _write(self):
        if not self.result_file:
            return
        now = time.time()
        tmp = self.result_file + ".tmp"
        with open(tmp, "w") as f:
            json.dump({"requests": self.n, "answered": len(self.answer_ms), "answer_ms": self.answer_ms,
                       "unanswered": sorted(q for q, t in self.sent.items() if now - t > 10.0)}, f)
        os.replace(tmp, self.result_file)


asker = Asker(component_name="asker", inputs=[answers], outputs=[questions], trigger=answers)

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[llm, asker], package_name="agent")
launcher.bringup()

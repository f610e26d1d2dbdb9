"""``TextToSpeech``: text in, speech out (WAV bytes on ``Audio`` topics, and/or the speakers).

Every text (each streamed piece of an LLM answer, too) is synthesized in arrival order. With
``play_on_device=True`` the audio is played through the default (or ``device``) output with
sounddevice when this machine has one. Without that output device (none here, no PortAudio, a
name or index that matches none) the component keeps publishing, but its health is
SYSTEM_FAILURE naming the device for as long as it runs, so ``on_system_fail`` fallbacks and
events can act (a restart looks for the device again). ``say(text)`` speaks on demand (an action
target) and ``stop_playback()`` cuts the current playback and drops what is queued.
"""
from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.io.topic import Topic
from emos.msgs import intelligence as I
from emos.msgs import sensor as S
from emos.msgs import std as D

from ..types import SpeechRequest
from .base import ModelComponent, ModelComponentConfig
from .convert import text_of


@define(kw_only=True)
class TextToSpeechConfig(ModelComponentConfig):
    play_on_device: bool = field(default=False)
    device: int | str | None = field(default=None)
    buffer_size: int = field(default=20, validator=V.in_range(1, 10_000))
    block_size: int = field(default=1024, validator=V.in_range(16, 1 << 20))
    thread_shutdown_timeout: float = field(default=5.0, validator=V.in_range(0.0, 600.0))
    #: accepted for the spec's recipes: every text (each streamed piece included) is synthesized
    #: and played as soon as it arrives, in order, whether or not this is set
    stream: bool = field(default=False)
    voice: str | None = field(default=None)
    speed: float | None = field(default=None)


def device_label(device: int | str | None) -> str:
    """How a report names the output device: the configured one, or the default."""
    return "the default audio output device" if device is None else f"audio output device {device!r}"


class _Player:
    """Plays WAV bytes one after the other on an output device, in its own thread.

    ``problem`` says why the device cannot be used (None when it can): then nothing plays."""

    def __init__(self, device: Any, buffer_size: int, log: Any) -> None:
        self.device, self.log = device, log
        self.queue: queue.Queue[bytes | None] = queue.Queue(maxsize=buffer_size)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tts-playback", daemon=True)
        self._sd: Any = None
        self.problem = self._open()
        self.available = self.problem is None
        if self.available:
            self._thread.start()

    def _open(self) -> str | None:
        try:
            import sounddevice as sd

            sd.query_devices(self.device, kind="output")
        except Exception as exc:  # no PortAudio, no such device: publishing still works
            return f"play_on_device: {device_label(self.device)} is not available here ({type(exc).__name__}: {exc})"
        self._sd = sd
        return None

    def play(self, wav: bytes) -> None:
        if not self.available:
            return
        try:
            self.queue.put_nowait(wav)
        except queue.Full:
            self.log.warning("playback queue full: an utterance was dropped")

    def stop_current(self) -> None:
        while True:
            try:
                self.queue.get_nowait()
            except queue.Empty:
                break
        if self._sd is not None:
            self._sd.stop()

    def _run(self) -> None:
        from ..local.audio import read_wav

        while not self._stop.is_set():
            wav = self.queue.get()
            if wav is None:
                return
            try:
                samples, rate = read_wav(wav)
                self._sd.play(samples, rate, device=self.device, blocking=True)
            except Exception as exc:
                self.log.error("playback failed: %s", exc)

    def close(self, timeout: float) -> None:
        self._stop.set()
        self.stop_current()
        if self._thread.is_alive():
            self.queue.put(None)
            self._thread.join(timeout)


class TextToSpeech(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = TextToSpeechConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = (D.String, I.StreamingString)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = (S.Audio,)

    def __init__(self, *, inputs: list[Topic], outputs: list[Topic] | None = None, model_client: Any,
                 config: TextToSpeechConfig | None = None, trigger: Any = 1.0, component_name: str, **kwargs: Any) -> None:
        super().__init__(inputs=inputs, outputs=outputs or [], model_client=model_client, config=config, trigger=trigger,
                         component_name=component_name, **kwargs)
        self.config: TextToSpeechConfig
        if not self.in_topics:
            raise ValueError(f"component {component_name!r}: TextToSpeech needs a String or StreamingString input")
        if not self.out_topics and not self.config.play_on_device:
            raise ValueError(f"component {component_name!r}: TextToSpeech with no output topic needs play_on_device=True")
        self._player: _Player | None = None
        self._device_problem: str | None = None  # why play_on_device cannot play (None: it can)
        self.utterances = 0

    def activate_resources(self) -> None:
        super().activate_resources()
        self._device_problem = None
        if self.config.play_on_device:
            self._player = _Player(self.config.device, self.config.buffer_size, self.get_logger())
            if self._player.problem is not None:
                self._device_problem = f"{self._player.problem}; audio is only published"
                self.get_logger().error("[%s] %s", self.component_name, self._device_problem)
                self._set_healthy()
                self._publish_status()

    def _set_healthy(self) -> None:
        """Healthy, unless the device to play on is missing: that lasts as long as this run of
        the component, whatever else works (a SYSTEM_FAILURE that fallbacks and events see)."""
        if self._device_problem is not None:
            self.health_status.set_fail_system(message=self._device_problem)
        else:
            self.health_status.set_healthy()

    def _clear_model_failure(self) -> None:
        if self._device_problem is None:
            super()._clear_model_failure()
            return
        self._set_healthy()
        self._publish_status()

    def release_resources(self) -> None:
        if self._player is not None:
            self._player.close(self.config.thread_shutdown_timeout)
            self._player = None
        super().release_resources()

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        topic = trigger if trigger is not None else self.in_topics[0]
        msg = inputs.get(topic.name)
        if msg is None:
            return None
        text = text_of(msg).strip()
        if not text:
            return None
        return lambda: self._speak(text)

    def _speak(self, text: str) -> None:
        request = SpeechRequest(text=text, voice=self.config.voice, speed=self.config.speed)
        response = self.call_model(lambda client: client.inference(request))
        if not response.audio:
            self.health_status.set_fail_algorithm(algorithm_names=[self.model_client_name], message="no audio for the text")
            return
        self.publish_all(response.audio)
        if self._player is not None:
            self._player.play(response.audio)
        self.utterances += 1
        self._set_healthy()

    # ------------------------------------------------------------------ actions
    def say(self, text: str) -> bool:
        """Speak ``text`` now (queued behind what is being spoken); False if not running."""
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"component {self.component_name!r}: say() needs a non-empty text")
        worker = self._worker
        return bool(worker is not None and worker.submit(lambda: self._run_job(lambda: self._speak(text.strip()))))

    def stop_playback(self) -> bool:
        """Stop what is playing and drop what is waiting to be played or synthesized."""
        worker = self._worker
        if worker is not None:
            worker.clear()
        if self._player is not None:
            self._player.stop_current()
        return True

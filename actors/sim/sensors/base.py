"""What every simulated sensor shares: a rate, a robot it rides on, a seeded RNG."""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..body import SimRobot
    from ..world import World


def check_rate(owner: str, rate_hz: float) -> float:
    rate_hz = float(rate_hz)
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"{owner}.rate_hz must be a finite number > 0, got {rate_hz!r}")
    return rate_hz


class Sensor:
    """Base class. The World calls ``on_tick`` every physics tick and ``read`` when the sensor
    is due (every ``1 / rate_hz`` simulated seconds); readings go to ``latest`` and to callbacks.
    """

    rate_hz: float = 10.0

    def __init__(self, robot: SimRobot, name: str) -> None:
        self.robot = robot
        self.name = name
        self.latest: Any = None
        self.world: World | None = None
        self.rng = np.random.default_rng(0)
        self._callbacks: list[Callable[[Any], None]] = []

    def bind(self, world: World, rng: np.random.Generator) -> None:
        self.world, self.rng = world, rng

    @property
    def bound_world(self) -> World:
        """The world the sensor is in (``World.add_sensor`` binds it before any tick or read)."""
        if self.world is None:
            raise RuntimeError(f"sensor {self.name!r} is in no world yet: World.add_sensor binds it")
        return self.world

    def subscribe(self, callback: Callable[[Any], None]) -> None:
        self._callbacks.append(callback)

    def on_tick(self, stamp: float) -> None:
        """Hook for sensors that must watch every tick (contacts)."""

    def read(self, stamp: float) -> Any:
        raise NotImplementedError

    def publish(self, stamp: float) -> Any:
        reading = self.read(stamp)
        self.latest = reading
        for callback in self._callbacks:
            callback(reading)
        return reading

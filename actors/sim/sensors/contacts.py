"""Collision contacts, gathered every tick and reported at the sensor's rate."""
from __future__ import annotations

from typing import TYPE_CHECKING

import attrs

from ..body import Contact
from .base import Sensor, check_rate

if TYPE_CHECKING:
    from ..body import SimRobot


@attrs.define(frozen=True, eq=False)
class ContactReading:
    stamp: float
    contacts: tuple[Contact, ...]  # every penetrating contact since the previous reading

    @property
    def in_collision(self) -> bool:
        return bool(self.contacts)


class ContactSensor(Sensor):
    def __init__(self, robot: SimRobot, rate_hz: float = 50.0, name: str = "contacts") -> None:
        super().__init__(robot, name)
        self.rate_hz = check_rate("ContactSensor", rate_hz)
        self._pending: list[Contact] = []

    def on_tick(self, stamp: float) -> None:
        # Contacts last one tick (the robot is stopped), so sample them all, not at the rate.
        self._pending.extend(self.robot.contacts)

    def read(self, stamp: float) -> ContactReading:
        pending, self._pending = self._pending, []
        return ContactReading(stamp, tuple(pending))

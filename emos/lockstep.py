"""``emos run --lockstep``: run a simulated recipe on simulated time, in lockstep.

ROS 2 users flip ``use_sim_time`` on at launch; this is that switch for a whole recipe, with
the stronger guarantee that EMOS's lockstep clock gives (:mod:`emos.core.clock`): the run's one
Simulator publishes ``/clock`` and waits, every tick, until each of the recipe's components has
handled it. A loaded or slow machine then slows the wall clock only; the robot sees every
command as it would on an idle one, so a run is repeatable and a test of it measures behaviour,
not the machine. The recipe itself is unchanged: the switch sets ``use_sim_time`` on every
component and makes them the Simulator's ``lockstep_consumers``.

An action loop in a thread of its own (the Controller's ``track_vision_target`` and path
actions) is covered too: it paces itself with ``Node.pacer``, which steps it inside its node's
ticks (``emos.core.clock.Pacer``). So is a detector that hands its frames to a worker thread
(``Vision``): its node answers a tick once the worker has done that tick's frames
(``SimTimeDriver.hold_ticks_for``). A language model's answers are not waited for (see
``ModelComponent.STEPS_INSIDE_TICKS``).

Left out on purpose: the monitor (a Cortex watching the run is an observer, not part of the
loop the simulator closes) and what the Launcher adds after the recipe's components (the web
UI, Foxglove, the ROS 2 bridge): they follow the wall clock as before.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

ENV_LOCKSTEP = "EMOS_LOCKSTEP"  # "1": `emos run --lockstep`


def requested() -> bool:
    return os.environ.get(ENV_LOCKSTEP) == "1"


def _is_simulator(component: Any) -> bool:
    # Duck-typed: the core does not import the Simulator (an actor, a layer above).
    return hasattr(component.config, "lockstep_consumers") and hasattr(component.config, "clock_mode")


def apply(components: Sequence[Any], monitor: Any | None = None) -> list[str]:
    """Put ``components`` on the one Simulator's lockstep clock; return the consumers' names.

    Raises ``ValueError`` naming what is wrong when the run has no Simulator or several.
    """
    simulators = [c for c in components if _is_simulator(c)]
    if len(simulators) != 1:
        found = ", ".join(repr(c.component_name) for c in simulators) or "none"
        raise ValueError(f"--lockstep runs a recipe on one Simulator's clock; this recipe has {len(simulators)} "
                         f"Simulator component(s) ({found})")
    sim = simulators[0]
    consumers = [c for c in components if c is not sim and c is not monitor and hasattr(c.config, "use_sim_time")]
    for c in consumers:
        c.config.use_sim_time = True
    names = list(sim.config.lockstep_consumers)
    names += [c.component_name for c in consumers if c.component_name not in names]
    sim.config.clock_mode = "lockstep"  # the config's converter makes it a ClockMode
    sim.config.lockstep_consumers = names
    return names

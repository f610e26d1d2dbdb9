"""Logic gates and composed events (seed recipe): & | ~ over several topics.

    emos run recipes/events_and_resilience/composed_events.py --duration 6

* smart stop: obstacle closer than 0.3 m AND moving faster than 0.1 m/s (``on_change``);
* conditional cognition: a person detected AND battery above 20 % (``keep_event_delay=5``);
* redundant sensors: front lidar closer than 0.2 m OR bumper pressed;
* exclusion: a person seen AND NOT in manual override.

Stand-ins: ``Scenario`` publishes a scripted drive (radar, odometry, bumper, battery,
detections, manual override) and ``DriveManager`` whose ``stop`` brakes the robot (it overrides
the lifecycle ``stop`` of BaseComponent, so the action runs inside it). Each event's action logs
a line naming the event. Radar and odometry have ``data_timeout``s: if the scenario stopped
publishing them, the smart stop could not fire on old data.

The script (seconds after the scenario starts): 0-1 s driving fast, far from obstacles;
1-2 s an obstacle at 0.25 m while fast (smart stop); 2-3 s slow near the obstacle (no stop);
3 s a person appears with 50 % battery (cognition, auto-track); 4 s the bumper is hit (collision).
"""
import logging
import time

import numpy as np

from emos import Action, BaseComponent, BaseComponentConfig, Event, Launcher, Topic
from emos.msgs import Bool, Detections, Float32, Odometry

radar = Topic(name="/radar_front", msg_type="Float32", data_timeout=0.2)
odom = Topic(name="/odom", msg_type="Odometry", data_timeout=0.5)
detections = Topic(name="/detections", msg_type="Detections")
battery = Topic(name="/battery_state", msg_type="Float32")
lidar = Topic(name="/scan_front", msg_type="Float32")
bumper = Topic(name="/bumper", msg_type="Bool")
manual_mode = Topic(name="/manual_override", msg_type="Bool")


class Scenario(BaseComponent):
    def custom_on_activate(self):
        self.t0 = time.monotonic()

    def _execution_step(self):
        t = time.monotonic() - self.t0
        speed = 0.05 if 2.0 <= t < 3.0 else 0.5
        distance = 0.25 if 1.0 <= t < 3.0 else 3.0
        o = Odometry()
        o.twist.twist.linear.x = speed
        # Radar before odometry: at 3 s the robot speeds up as the obstacle goes; the other order
        # would briefly be "fast and close" (the Monitor sees messages in publish order).
        self.publish(radar, Float32(data=distance))
        self.publish(odom, o)
        self.publish(lidar, Float32(data=distance + 0.5))
        self.publish(bumper, Bool(data=t >= 4.0))
        self.publish(battery, Float32(data=50.0))
        self.publish(manual_mode, Bool(data=False))
        labels = ["person"] if t >= 3.0 else []
        self.publish(detections, Detections(labels=labels, scores=np.ones(len(labels)), boxes=np.zeros((len(labels), 4))))
        self.health_status.set_healthy()


class DriveManager(BaseComponent):
    def stop(self):
        """Brake (the robot's stop, not the component's lifecycle stop)."""
        self.get_logger().info("[drive_manager] EMERGENCY STOP (smart stop)")
        return True


def announce(what: str):
    logging.getLogger("recipe").info("EVENT %s", what)


scenario = Scenario(component_name="scenario", outputs=[radar, odom, detections, battery, lidar, bumper, manual_mode],
                    config=BaseComponentConfig(loop_rate=20.0))
driver = DriveManager(component_name="drive_manager")

# Navigation: smart emergency stop
is_obstacle_close = radar.msg.data < 0.3
is_robot_moving_fast = odom.msg.twist.twist.linear.x > 0.1
event_smart_stop = Event(event_condition=(is_obstacle_close & is_robot_moving_fast), on_change=True)

# Intelligence: conditional cognition
person_detected = detections.msg.labels.contains_any(["person"])
battery_ok = battery.msg.data > 20.0
event_describe_person = Event(event_condition=(person_detected & battery_ok), on_change=True, keep_event_delay=5)

# OR: redundant sensors
is_lidar_blocked = lidar.msg.data < 0.2
is_bumper_pressed = bumper.msg.data == True  # noqa: E712 (a condition, not a comparison)
event_any_collision = Event(event_condition=(is_lidar_blocked | is_bumper_pressed), on_change=True)

# NOT: exclusion
target_seen = detections.msg.labels.contains_any(["person"])
event_auto_track = Event(event_condition=(target_seen & ~manual_mode.msg.data), on_change=True)

events_actions = {
    event_smart_stop: Action(method=driver.stop),
    event_describe_person: Action(announce, args=("describe person (battery ok)",)),
    event_any_collision: Action(announce, args=("collision (lidar or bumper)",)),
    event_auto_track: Action(announce, args=("auto-track person (not in manual mode)",)),
}

launcher = Launcher()
launcher.add_pkg(components=[scenario, driver], events_actions=events_actions, multiprocessing=True)
launcher.bringup()

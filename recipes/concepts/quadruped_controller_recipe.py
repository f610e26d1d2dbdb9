"""quadruped_controller_recipe.py of the events-and-actions page (concepts/events-and-actions.md):
when the terrain a perception node publishes on /terrain_type changes, the quadruped's
controller switches its gait, given the terrain read from the topic.

    cd recipes/concepts && emos run quadruped_controller_recipe.py
    emos topic pub /terrain_type String '{"data": "stairs"}'   # -> "New terrain detected! Switching gait."

The spec's code with its imports changed (``my_pkg.components`` is quadruped_controller.py
beside this file) and the errata's three fixes: the action calls the component's
``switch_gait_controller`` (the page's ``self.activate_stairs_controller`` does not exist) with
``args`` a tuple, the events map uses ``event_terrain_changed`` (the page's ``stairs_event`` is
undefined), and the recipe ends with ``bringup()``.
"""
from quadruped_controller import QuadrupedController

from emos import Action, Event, Launcher, Topic

quad_controller = QuadrupedController(component_name="quadruped_controller")

# Define the Event Topic
terrain_topic = Topic(name="/terrain_type", msg_type="String")

# Define the Event
# Logic: Trigger when the detected terrain changes
# on_change=True ensures we only trigger the switch the FIRST time stairs are seen.
# Add an optional delay to prevent rapid event triggering
event_terrain_changed = Event(terrain_topic, on_change=True, keep_event_delay=60.0)

# Define the Action
# Call self.switch_gait_controller() when triggered and pass the detected terrain to the method
change_gait_action = Action(method=quad_controller.switch_gait_controller, args=(terrain_topic.msg.data,))  # errata

# Register
my_launcher = Launcher()
my_launcher.add_pkg(
    components=[quad_controller],
    events_actions={event_terrain_changed: change_gait_action},  # errata
)
my_launcher.bringup()  # errata: the page never brings the recipe up

"""The extending page's recipe (advanced/extending.md, step 6): the custom component of
my_awesome_pkg/ in a process of its own, an event that logs when the battery is low, and a
restart on any component failure.

    cd recipes/extending && emos run awesome_recipe.py
    emos topic pub /battery_level Float32 '{"data": 12.0}'    # logs "Battery is Low!"

The spec's code with its imports changed and the errata's fixes: ``Dict``, ``Event``,
``Action`` and ``event`` imported, and ``battery_level_topic`` defined (the page uses it
without defining it). Steps 1 and 5 of the page (a ROS 2 package, its ``setup.py`` and an
``executable`` entry point built on ``ros_sugar.executable_main``) are not needed: EMOS runs a
component in a process of its own without an entry point, and ``add_pkg`` accepts
``package_name`` and ``executable_entry_point`` so these lines port unchanged.
"""

from my_awesome_pkg.awesome_component import AwesomeComponent, AwesomeConfig  # noqa: F401 - as on the page

from emos import Action, Event, Launcher, Topic  # errata: Event, Action not imported on the page
from emos import events as event  # errata: `event` not imported on the page
from emos.actions import LogInfo
from emos.events import OnLess  # noqa: F401 - the page imports it

# Define a set of topics
map_topic = Topic(name="map", msg_type="OccupancyGrid")
audio_topic = Topic(name="voice", msg_type="Audio")
image_topic = Topic(name="camera/rgb", msg_type="Image")
battery_level_topic = Topic(name="battery_level", msg_type="Float32")  # errata: undefined on the page

# Init your components
my_component = AwesomeComponent(
    component_name='awesome_component',
    inputs=[map_topic, image_topic],
    outputs=[audio_topic]
)

# Create your events
low_battery = Event(battery_level_topic.msg.data < 15.0)

# Events/Actions
my_events_actions: dict[event.Event, Action] = {
    low_battery: LogInfo(msg="Battery is Low!")
}

# Create your launcher
launcher = Launcher()

# Add your package components
launcher.add_pkg(
    components=[my_component],
    package_name='my_awesome_pkg',
    executable_entry_point='executable',
    events_actions=my_events_actions,
    activate_all_components_on_start=True,
    multiprocessing=True,
)

# If any component fails -> restart it with unlimited retries
launcher.on_component_fail(action_name="restart")

# Bring up the system
launcher.bringup()

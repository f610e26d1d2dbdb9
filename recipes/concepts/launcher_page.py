"""The launcher page's recipe (concepts/launcher.md): two components in their own processes, a
restart fallback, a low-battery event that logs, and a configuration file.

    cd recipes/concepts && emos run launcher_page.py
    emos topic pub /battery Float32 '{"data": 12.0}'      # logs "WARNING: Battery Low!"

The spec's code with its imports changed. The page's ``config/robot_params.toml`` is not on the
page (errata): recipes/concepts/config/robot_params.toml is one; the path is relative, as on
the page, so run the recipe from this folder. ``fallback=`` is kept (the errata's ``action=``
works too: ``on_component_fail`` takes both).
"""
from emos import Action, BaseComponent, Event, Launcher, Topic  # noqa: F401 - the page imports Action
from emos.actions import log, restart

# 1. Define Components
# (Usually imported from your package)
driver = BaseComponent(component_name='lidar_driver')
planner = BaseComponent(component_name='path_planner')

# Set Fallback Policy
# If the driver crashes, try to restart it automatically
driver.on_component_fail(fallback=restart(component=driver))

# 2. Define Logic for Events
battery = Topic(name="/battery", msg_type="Float32")
low_batt_evt = Event(battery.msg.data < 15.0)

log_action = log(msg="WARNING: Battery Low!")

# 3. Initialize Launcher
launcher = Launcher(
    config_file='config/robot_params.toml',     # Can optionally pass a configuration file
    activate_all_components_on_start=True,
    multi_processing=True # Use separate processes
)

# 4. Register Components
# You can attach specific events to specific groups of components
launcher.add_pkg(
    components=[driver, planner],
    ros_log_level="error",
    events_actions={low_batt_evt: log_action}
)

# 5. Launch!
# This blocks until Ctrl+C is pressed
launcher.bringup()

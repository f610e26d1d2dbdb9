"""The ``kompass_sim`` share directory: the files the spec's navigation recipes load from it.

The spec's recipes read their maps from the ROS package ``kompass_sim``::

    kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")
    map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml")

This folder is that share directory for :func:`emos.packages.get_package_share_directory`
(registered as the entry point ``kompass_sim`` in the group ``emos.packages``). ``maps/`` holds
ROS map_server maps (YAML + trinary PGM, 0.05 m) of the two TurtleBot3 worlds the spec's
simulators run, drawn from those worlds' walls and furniture by
:mod:`emos.actors.sim.data.kompass_sim.generate_maps` (run it to rebuild them; a test checks the
shipped files equal its output):

* ``turtlebot3_webots``: the webots_ros2 TurtleBot3 arena (5 x 10 m, furniture), in the frame
  the robot's odometry starts in: the robot starts at (0, 0) facing +x;
* ``turtlebot3_gazebo_house``: the turtlebot3_gazebo house (15 x 10.5 m, six rooms and a
  front yard), in the Gazebo world's frame; kompass_sim spawns the robot at (0.1, 0.2).

The ``Simulator`` builds the same world from either file (``SimulatorConfig(world=map_file)``
extrudes the occupied cells into walls), so the MapServer's map and the simulated walls agree.
"""

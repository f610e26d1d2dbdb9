"""The system ``emos bench barn`` runs per world in process mode: the Simulator (the world, the
robot, its lidar and odometry, lock-step clock) and the navigation components configured as the
built-in navigator is, each in its own process under the supervisor.

    LocalMapper (mapping mode: lidar obstacle memory + scan matching; localized pose)
      -> Planner (CostToGo on that memory, towards /goal)
      -> Controller (ArcSampler by default, on the local map)
      -> DriveManager (safety zones, limits) -> /cmd_vel -> Simulator

The stack sees only what a robot would: the scan, the odometry the simulated robot's wheels
give (ground truth unless ``noisy_odometry``: the rules' choice, as in-process) and the goal.
The Simulator's transform tree (its world -> odom link is computed from the true pose), its map
and its ground-truth output are never wired to a navigation component; ground truth goes to
the harness's referee only (:data:`GROUND_TRUTH_TOPIC`).

:func:`build_system` returns the components without starting anything (tests inspect it);
:func:`bringup` is what the generated recipe calls.
"""
from __future__ import annotations

from typing import Any

import attrs

from emos.actors.sim.barn_trial import start_and_goal
from emos.actors.sim.jackal import JACKAL_ODOMETRY
from emos.actors.sim.robots import PRESETS

from .harness import BarnRules, nav_robot

GROUND_TRUTH_TOPIC = "/barn/ground_truth"
GOAL_TOPIC = "/goal"
PLAN_TOPIC = "/plan"  # the Planner's output and the Controller's input, both at their defaults
LOCALIZED_POSE_TOPIC = "/local_map/pose"  # the LocalMapper's scan-matched pose: where the stack believes it is
NAV_COMPONENTS = ("mapper", "planner", "controller", "driver")
SIM_NAME = "sim"

# --controller name (as in-process) -> (ControllersID value, scan matching in the mapper)
PROCESS_CONTROLLERS: dict[str, tuple[str, bool]] = {
    "builtin": ("ArcSampler", True),
    "builtin-odom": ("ArcSampler", False),
    "builtin-robust": ("ArcSampler", True),  # with the response model (ROBUST_CONTROLLERS)
    "builtin-dynamic": ("ArcSampler", True),  # and moving obstacles (DYNAMIC_CONTROLLERS)
    "navcore-dwa": ("DWA", True),
    "navcore-purepursuit": ("PurePursuit", True),
    "navcore-stanley": ("Stanley", True),
    "navcore-dvz": ("DVZ", True),
    "mppi": ("MPPI", True),  # Nav2's MPPI (emos.actors.nav.controllers.mppi)
    "rpp": ("RegulatedPurePursuit", True),  # Nav2's Regulated Pure Pursuit
}

# --controller names whose ArcSampler checks the arcs the base achieves (ResponseConfig)
ROBUST_CONTROLLERS = ("builtin-robust", "builtin-dynamic")
# --controller names for moving obstacles: the mapper's memory forgets by evidence
# (EvidenceConfig), the ArcSampler tracks movers and checks arcs against them (MoverConfig)
DYNAMIC_CONTROLLERS = ("builtin-dynamic",)


@attrs.define(frozen=True)
class RecoveryOptions:
    """The stack's stuck recovery (the in-process navigator's: back out, then block the plan's
    tightest spot). ``progress_timeout`` s without ``progress_distance`` m of progress is a
    stall; ``backup_distance`` m per back-out; ``attempts`` back-out + block pairs before giving
    up; ``rate`` (Hz): at most this many fallback steps per second of wall time."""

    enabled: bool = True
    progress_timeout: float = 3.0
    progress_distance: float = 0.3
    backup_distance: float = 0.5
    attempts: int = 4
    rate: float = 1.0


@attrs.define(frozen=True)
class StackOptions:
    """One trial's system. ``rules`` (the harness's TrialSpec) carries the robot model and the
    sensor configuration (ideal or realistic, robot, odometry, rates): the same choices as
    in-process. ``dynabarn``: ``world`` indexes the moving-obstacle set, not BARN."""

    world: int
    rules: BarnRules = attrs.field(factory=BarnRules)
    algorithm: str = "ArcSampler"
    scan_matching: bool = True
    barn_source: str | None = None
    seed: int = 0
    clock_rate: float = 50.0
    window_margin: float = 3.0  # m around start and goal mapped (as the built-in navigator's memory)
    response_model: bool = False  # ArcSamplerConfig(response=ResponseConfig()): builtin-robust
    moving_obstacles: bool = False  # evidence memory + ArcSamplerConfig(movers=MoverConfig()): builtin-dynamic
    dynabarn: bool = False
    recovery: RecoveryOptions = attrs.field(factory=RecoveryOptions)
    swept_check: bool = True  # the DriveManager's swept-footprint check (docs/safety.md); off: the zones alone

    @classmethod
    def for_controller(cls, name: str, **kwargs: Any) -> StackOptions:
        try:
            algorithm, matching = PROCESS_CONTROLLERS[name]
        except KeyError:
            raise ValueError(f"controller {name!r} has no process-mode stack; choose from {sorted(PROCESS_CONTROLLERS)} "
                             "or run it with --in-process") from None
        return cls(algorithm=algorithm, scan_matching=matching, response_model=name in ROBUST_CONTROLLERS,
                   moving_obstacles=name in DYNAMIC_CONTROLLERS, **kwargs)

    def entry(self) -> Any:
        """The world this system runs (a ``BarnWorld`` or, with ``dynabarn``, a ``DynaWorld``)."""
        if self.dynabarn:
            from emos.actors.sim.dynabarn import load_dynabarn

            worlds: dict = load_dynabarn()
        else:
            from emos.actors.sim.barn_worlds import load_barn_worlds

            worlds = load_barn_worlds(self.barn_source)
        if self.world not in worlds:
            raise ValueError(f"StackOptions.world: no {'DynaBARN' if self.dynabarn else 'BARN'} world {self.world}")
        return worlds[self.world]


def build_system(opts: StackOptions) -> tuple[Any, list[Any]]:
    """(simulator, [mapper, planner, controller, driver]), configured, nothing started."""
    from emos.actors.nav import MapConfig
    from emos.actors.nav.components import (
        Controller,
        ControllerConfig,
        DriveManager,
        DriveManagerConfig,
        LocalMapper,
        LocalMapperConfig,
        Planner,
        PlannerConfig,
    )
    from emos.actors.nav.mapping import EvidenceConfig
    from emos.actors.nav.robot import RobotFrames
    from emos.actors.sim.component import Simulator, SimulatorConfig
    from emos.io.topic import Topic

    rules = opts.rules
    lidar = rules.lidar
    spec = PRESETS[rules.robot_name]
    # One fixed frame: odometry starts at the start pose in world coordinates (as the robot is
    # told where it starts), so the memory, the plan and the poses share it.
    frames = RobotFrames(world="map", odom="map")
    robot = nav_robot(spec)
    if rules.ideal:  # the kinematic Jackal, a UST-10-like lidar, true or drifting wheel odometry
        sensors: dict[str, Any] = dict(
            odometry_mode="wheel" if rules.noisy_odometry else "truth", odom_rate=rules.control_rate_hz * 2,
            slip=rules.slip if rules.noisy_odometry else 0.0, scan_rate=lidar.rate_hz, scan_beams=lidar.beams,
            scan_fov_deg=lidar.fov_deg, scan_range_max=lidar.range_max, scan_noise_std=lidar.noise_std)
    else:  # the robot preset's drive model, the Jackal's laser, wheel + IMU odometry
        sensors = dict(odometry_mode="wheel-imu", odom_rate=JACKAL_ODOMETRY.rate_hz, scan_preset="jackal")
    start, goal = start_and_goal(opts.entry())
    sim = Simulator(SIM_NAME, config=SimulatorConfig(
        world=f"{'dynabarn' if opts.dynabarn else 'barn'}:{opts.world}", barn_source=opts.barn_source,
        robot=rules.robot_name, spawn=start,
        frames=frames, physics_rate=1.0 / rules.physics_dt, clock_rate=opts.clock_rate, clock_mode="lockstep",
        lockstep_consumers=list(NAV_COMPONENTS), seed=opts.seed,
        # The stack's compute time charged as in-process: its commands act that much later.
        compute_deadline=1.0 / rules.control_rate_hz if rules.charges_compute else None, **sensors))
    # Nothing that carries the true pose reaches the stack: no /tf (its world -> odom link is
    # computed from the true pose), no map; ground truth on a topic only the referee reads.
    sim.outputs(tf=None, ground_truth=Topic(name=GROUND_TRUTH_TOPIC, msg_type="Odometry"))

    sx, sy, _ = start
    gx, gy = goal
    m = opts.window_margin
    bounds = (min(sx, gx) - m, min(sy, gy) - m, max(sx, gx) + m, max(sy, gy) + m)
    # The scan-matched pose with the odometry's measured twist: the Controller's response model
    # (builtin-robust, builtin-dynamic) estimates the yaw gain from what the base does, as the
    # in-process navigator does from the odometry's twist (a PoseStamped has no twist: the
    # Controller would fall back to its own last command).
    pose_topic = Topic(name=LOCALIZED_POSE_TOPIC, msg_type="Odometry")
    memory_topic = Topic(name="/local_map/memory", msg_type="OccupancyGrid")
    common = dict(robot=robot, frames=frames, use_sim_time=True)
    mount = (*lidar.mount_xy, lidar.mount_yaw)
    mapper = LocalMapper("mapper", config=LocalMapperConfig(
        map_params=MapConfig(width=6.0, height=6.0, resolution=0.05), keep_memory=True, sensor_pose=mount,
        mapping_bounds=bounds, scan_matching=opts.scan_matching, map_publish_period=0.0,
        memory_decay=EvidenceConfig() if opts.moving_obstacles else None,
        local_map_frame="robot" if opts.moving_obstacles else "world", **common))
    mapper.run_type = "Event"
    mapper.outputs(mapping=memory_topic, localized_pose=pose_topic)
    planner = Planner("planner", config=PlannerConfig(planner_id="CostToGo", loop_rate=1.0, **common))
    # No pixel goals here, so neither the camera nor /tf (the stack never sees a true pose).
    planner.inputs(map=memory_topic, goal_point=Topic(name=GOAL_TOPIC, msg_type="PointStamped"), location=pose_topic,
                   tf=None, depth_camera_info=None)
    recovery = opts.recovery
    controller = Controller("controller", config=ControllerConfig(
        algorithm=opts.algorithm, loop_rate=rules.control_rate_hz, control_time_step=1.0 / rules.control_rate_hz,
        use_direct_sensor=False, fallback_rate=recovery.rate,
        progress_timeout=recovery.progress_timeout if recovery.enabled else 0.0,
        progress_distance=recovery.progress_distance,
        failure_tolerance=recovery.progress_timeout if recovery.enabled else 0.0, **common))
    # Static worlds: the ego-centric grid of the latest scan, published in the world frame at
    # its scan's pose, so the controller places it by its own origin. Read with the controller's
    # latest pose instead, it lands a scan's motion away, since in lock-step that pose is often
    # the scan before's (51 of 126 control steps in world 19: up to 4 cm at 2 m/s, against a
    # 1.5 cm margin). The never-forgetting memory, placed right too, piles up every scan's range
    # noise: obstacles about 2 cm wider per side (worlds 62, 117, 111, 112 x 10: 37/50 on the
    # memory, 48/50 on this grid; docs/benchmarks-history.md, "World 62"). Moving obstacles: the memory that forgets
    # by evidence, as tuned.
    controller.inputs(location=pose_topic, local_map=memory_topic if opts.moving_obstacles else mapper.get_out_topic("local_map"))
    if opts.response_model or opts.moving_obstacles:
        from emos.actors.nav.controllers import ArcSamplerConfig
        from emos.actors.nav.controllers.arcs import ArcConfig
        from emos.actors.nav.controllers.movers import MoverConfig
        from emos.actors.nav.controllers.response import ResponseConfig

        extra: dict[str, Any] = {}
        if opts.moving_obstacles:
            # The in-process navigator's arcs, backing-up arcs included: the one way to stand
            # aside from a mover coming head-on (the local map remembers what is behind).
            extra["arcs"] = ArcConfig()
        controller.algorithms_config = ArcSamplerConfig(
            response=ResponseConfig() if opts.response_model else None,
            movers=MoverConfig() if opts.moving_obstacles else None, control_time_step=1.0 / rules.control_rate_hz,
            **extra)
    elif opts.algorithm == "MPPI":
        from emos.actors.nav.controllers import MPPIConfig

        # Nav2's sampling spread (vx_std 0.2, wz_std 0.4) is for a 0.5 m/s robot; for the 2 m/s
        # Jackal the sequence gained speed so slowly that BARN runs took 50 s. Tuned on the
        # shipped worlds with idx % 6 in {1, 2} (docs/benchmarks.md).
        controller.algorithms_config = MPPIConfig(vx_std=0.4, wz_std=0.6, control_time_step=1.0 / rules.control_rate_hz)
    if opts.moving_obstacles:  # obstacles from the local map; moving ones tracked in the scan
        controller.inputs(sensor_data=Topic(name="/scan", msg_type="LaserScan"))
    control = Topic(name="/control", msg_type="Twist")
    controller.outputs(command=control)
    driver = DriveManager("driver", config=DriveManagerConfig(
        critical_zone_distance=0.02, slowdown_zone_distance=0.05, max_distance=recovery.backup_distance, sensor_pose=mount,
        swept_check=opts.swept_check, **common))
    driver.inputs(command=control)
    driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
    if recovery.enabled:
        wire_recovery(controller, planner, driver, recovery)
    return sim, [mapper, planner, controller, driver]


def wire_recovery(controller: Any, planner: Any, driver: Any, recovery: RecoveryOptions) -> None:
    """The stuck recovery, as a recipe author writes it with the product's fallbacks: the
    Controller reports a stall (its progress checker) as an ALGORITHM failure; the ladder backs
    out with the DriveManager (straight back, checked against the scan) and then blocks the
    plan's tightest spot in the Planner (which re-plans around it), ``recovery.attempts``
    times; then the Controller gives up (GAVE_UP in ``emos status``, ``on_giveup`` logs it)."""
    from emos import Action
    from emos.actions import log

    ladder = [Action(method=driver.move_backward), Action(method=planner.block_tightest_spot)] * recovery.attempts
    controller.on_algorithm_fail(action=ladder, max_retries=1)
    controller.on_giveup(action=log(msg=f"controller: stuck recovery spent ({recovery.attempts} back-outs and blocks); "
                                        "the robot stays where it is"))


# Modules the navigation components import lazily, on their first map, plan or clearance query
# (the cost-to-go planner's scipy.ndimage and csgraph, the controller's k-d tree, the mapper's
# distance transform). Every component process is forked from this recipe process (the
# supervisor's zygote), so what is imported here before bring-up is imported once per trial
# instead of once per component, and not in a component's step: measured per trial, 2.5 s of
# CPU time in the planner, controller and mapper against about 1.3 s here.
PRELOADED_MODULES = ("scipy.ndimage", "scipy.sparse", "scipy.sparse.csgraph", "scipy.spatial")


# A trial's components count as hung after this long without a status message (the product's
# default is 2 s). On the shared machine at load 20-50 with `nice -n 10` the supervisor killed a
# trial's Simulator as hung 6-12 s into its drive, trial after trial: a system failure that says
# nothing of the navigation. The referee's wall timeout (`--wall-timeout`) bounds a real hang.
HEARTBEAT_TIMEOUT_S = 30.0


def preload() -> None:
    """Import :data:`PRELOADED_MODULES` (a missing one is left to the component that needs it,
    which says so in its own words)."""
    import importlib

    for name in PRELOADED_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            pass


def bringup(opts: StackOptions) -> int:
    """Run the system under the supervisor until stopped (the generated recipe's body)."""
    from emos import Launcher

    sim, nav = build_system(opts)
    preload()
    launcher = Launcher(multi_processing=True, heartbeat_timeout=HEARTBEAT_TIMEOUT_S)
    launcher.add_pkg(components=[sim])
    launcher.kompass(components=nav, multiprocessing=True)
    return launcher.bringup()


def recipe_source(opts: StackOptions) -> str:
    """The recipe file ``emos run`` executes for one world."""
    fields = {a.name: getattr(opts, a.name) for a in attrs.fields(StackOptions) if a.name not in ("rules", "recovery")}
    rules = attrs.asdict(opts.rules)
    recovery = attrs.asdict(opts.recovery)
    return (
        "from emos.tools.barn.stack import RecoveryOptions, StackOptions, bringup\n"
        "from emos.tools.barn.harness import BarnRules\n"
        f"bringup(StackOptions(rules=BarnRules(**{rules!r}), recovery=RecoveryOptions(**{recovery!r}), **{fields!r}))\n"
    )


__all__ = ["DYNAMIC_CONTROLLERS", "GROUND_TRUTH_TOPIC", "GOAL_TOPIC", "LOCALIZED_POSE_TOPIC", "NAV_COMPONENTS", "PLAN_TOPIC", "PROCESS_CONTROLLERS", "RecoveryOptions", "SIM_NAME",
           "StackOptions", "build_system", "bringup", "preload", "HEARTBEAT_TIMEOUT_S", "PRELOADED_MODULES", "recipe_source", "wire_recovery"]

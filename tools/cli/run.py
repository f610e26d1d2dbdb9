"""``emos run RECIPE.py``: execute a recipe as ``__main__`` under the supervisor."""
from __future__ import annotations

import argparse
import math
import os
import runpy
import sys
from typing import Any

EXIT_NO_BRINGUP = 5  # the supervisor's own codes: 3 gave up, 4 a component failed to start


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a finite number of seconds > 0, got {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recipe", help="recipe name (see `emos ls`) or path of the recipe script")
    parser.add_argument("--duration", type=_seconds, default=None, help="stop by itself after this many seconds")
    parser.add_argument("--no-log", action="store_true", help="do not keep a copy of the output in ~/emos/logs")
    parser.add_argument("--zenoh", metavar="CONFIG", default=None,
                        help="Zenoh configuration file (mode, endpoints, TLS, access control) to reach other hosts; "
                             "without one, Zenoh stays on this host's loopback")
    parser.add_argument("--secure", metavar="KEYSTORE", default=None,
                        help="Zenoh with mutual TLS and the access rules of `emos security policy` for this recipe (the identity's "
                             "file in KEYSTORE/policies/, or --zenoh FILE); refuses any configuration that is not secure")
    parser.add_argument("--identity", metavar="NAME", default=None, help="with --secure: the identity this host runs as")
    parser.add_argument("--net-topics", metavar="TOPICS", default=None, help="topics over Zenoh: 'all' or names separated by ','; default: those a recipe marks transport='zenoh'")
    parser.add_argument("--net-services", metavar="NAMES", default=None, help="services and actions also served over Zenoh: 'all' or names separated by ','")
    parser.add_argument("--net-control", action="store_true",
                        help="with --zenoh: let the Monitors of other runs in the group act on this run's components "
                             "(methods, parameters, start/stop/restart, their services and goals)")
    parser.add_argument("--ros2", action="store_true",
                        help="bridge the run's topics to live ROS 2 nodes (a supervised bridge process; needs ROS 2: pip install 'emos[ros2]')")
    parser.add_argument("--ros2-topics", metavar="TOPICS", default=None,
                        help="with --ros2: 'all' (default) or topic names / wildcards separated by ','")
    parser.add_argument("--ros-domain-id", metavar="N", type=int, default=None, help="with --ros2: the ROS 2 domain id (default: $ROS_DOMAIN_ID, else 0)")
    parser.add_argument("--lockstep", action="store_true",
                        help="run on the recipe's Simulator clock: it waits every tick for each component (use_sim_time on all), "
                             "so a slow or busy machine slows the run, not the robot's reactions")
    parser.add_argument("--ui-host", metavar="ADDRESS", default=None, help="serve the recipe's web UI on this address (e.g. 0.0.0.0: HTTPS and pairing, docs/ui.md)")
    parser.add_argument("--ui-https", action="store_true", help="serve the web UI over HTTPS on loopback too (off loopback it always is)")
    parser.add_argument("--ui-cert", metavar="FILE", default=None, help="the web UI's certificate (PEM), with --ui-key; default: the keystore's or a self-signed one")
    parser.add_argument("--ui-key", metavar="FILE", default=None, help="the private key of --ui-cert (PEM)")
    parser.add_argument("--ui-keystore", metavar="DIR", default=None, help="serve the web UI with the certificate of the identity 'ui' in this EMOS keystore")
    parser.add_argument("args", nargs="*", help="arguments for the recipe, after '--'")


def run(args: argparse.Namespace) -> int:
    from emos.supervisor.recipes import RecipeNotFound, resolve_recipe

    try:
        path = resolve_recipe(args.recipe)
    except RecipeNotFound as exc:
        print(f"emos run: {exc}", file=sys.stderr)
        return 2
    if not args.no_log:
        from emos.supervisor.runlog import start_run_log

        start_run_log(path, sys.argv[1:])
    import emos.launcher as launcher_mod

    launcher_mod._RUN_DURATION = args.duration
    os.environ["EMOS_RUN_CLI"] = "1"
    if getattr(args, "lockstep", False):
        from emos.lockstep import ENV_LOCKSTEP

        os.environ[ENV_LOCKSTEP] = "1"
    problem = _secure_options(args, path) or _network_options(args) or _ros2_options(args) or _ui_options(args)
    if problem:
        print(f"emos run: {problem}", file=sys.stderr)
        return 2
    sys.argv = [str(path), *args.args]
    sys.path.insert(0, str(path.resolve().parent))
    launcher_mod.Launcher.last_exit_code = None
    runpy.run_path(str(path), run_name="__main__")
    code = launcher_mod.Launcher.last_exit_code
    if code is None:
        # A recipe that only defines components ran nothing: say so rather than succeed.
        print(f"emos run: {path} finished without bringing anything up: it never called Launcher.bringup()", file=sys.stderr)
        return EXIT_NO_BRINGUP
    return code


def _secure_options(args: argparse.Namespace, path: Any) -> str | None:
    """``--secure KEYSTORE [--identity NAME]`` (emos.tools.cli.security)."""
    if getattr(args, "secure", None) is None:
        return "--identity goes with --secure" if getattr(args, "identity", None) else None
    from emos.tools.cli.security import secure_run_options

    problem = secure_run_options(args.secure, args.identity, args.zenoh, path)
    args.zenoh = None  # exported by --secure, checked
    return problem


def _network_options(args: argparse.Namespace) -> str | None:
    """Export ``--zenoh`` / ``--net-topics`` to the run (components inherit the environment)."""
    from emos.transport.select import ENV_NET_TOPICS, net_topics_option
    from emos.transport.zenoh_config import ENV_ZENOH_CONFIG

    if args.zenoh is not None:
        path = os.path.abspath(args.zenoh)
        if not os.path.isfile(path):
            return f"--zenoh {args.zenoh!r}: no such Zenoh configuration file"
        os.environ[ENV_ZENOH_CONFIG] = path
    if args.net_control:
        if args.zenoh is None and not os.environ.get(ENV_ZENOH_CONFIG):
            return "--net-control serves this run's components over Zenoh: give --zenoh CONFIG too"
        from emos.transport.zenoh_control import ENV_NET_CONTROL

        os.environ[ENV_NET_CONTROL] = "on"
    if args.net_services is not None:
        from emos.transport.select import ENV_NET_SERVICES

        os.environ[ENV_NET_SERVICES] = args.net_services
    if args.net_topics is not None:
        os.environ[ENV_NET_TOPICS] = args.net_topics
        try:
            net_topics_option()
        except ValueError as exc:
            return f"--net-topics: {exc}"
    return None


def _ui_options(args: argparse.Namespace) -> str | None:
    """Export the --ui-* flags to the run (emos.actors.ui.launch reads them; they win over the recipe)."""
    if bool(args.ui_cert) != bool(args.ui_key):
        return "--ui-cert and --ui-key go together"
    for flag, value, env in (("--ui-cert", args.ui_cert, "EMOS_UI_CERTFILE"), ("--ui-key", args.ui_key, "EMOS_UI_KEYFILE"),
                             ("--ui-keystore", args.ui_keystore, "EMOS_UI_KEYSTORE")):
        if value:
            path = os.path.abspath(os.path.expanduser(value))
            if not os.path.exists(path):
                return f"{flag} {value!r}: no such file or directory"
            os.environ[env] = path
    secure = getattr(args, "secure", None)
    if secure and not args.ui_keystore and not args.ui_cert and os.path.isdir(os.path.join(secure, "identities", "ui")):
        # `--secure KEYSTORE` with an identity "ui" in it: the web UI serves that certificate when it serves HTTPS.
        os.environ["EMOS_UI_KEYSTORE"] = os.path.abspath(secure)
    if args.ui_https:
        os.environ["EMOS_UI_TLS"] = "on"
    if args.ui_host:
        os.environ["EMOS_UI_HOST"] = args.ui_host
    return None


def _ros2_options(args: argparse.Namespace) -> str | None:
    """Export ``--ros2`` / ``--ros2-topics`` / ``--ros-domain-id`` to the run (emos.transport.select.use_ros2
    checks them); without ROS 2 installed, fail now, saying what to install."""
    ros2 = getattr(args, "ros2", False)
    if not ros2:
        if getattr(args, "ros2_topics", None) is not None or getattr(args, "ros_domain_id", None) is not None:
            return "--ros2-topics and --ros-domain-id go with --ros2"
        return None
    from emos.transport.select import use_ros2

    try:
        install = use_ros2(topics=args.ros2_topics, domain_id=args.ros_domain_id)
    except (ImportError, ValueError, TypeError) as exc:
        return f"--ros2: {exc}"
    print(f"emos run: bridging to {install}", file=sys.stderr)
    return None

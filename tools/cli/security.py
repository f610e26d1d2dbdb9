"""``emos security``: a keystore (a CA), identities it signs, and Zenoh access rules + TLS
configuration derived from a recipe (the logic is :mod:`emos.security`)."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

EXAMPLES = """examples:
  emos security create-keystore ~/emos-keys
  emos security create-identity ~/emos-keys robot1 --host robot1.local --host 192.168.1.20
  emos security create-identity ~/emos-keys alice                   # an operator
  emos security policy point_navigation --keystore ~/emos-keys --identity robot1 --operator alice \\
      --listen tls/0.0.0.0:7447 --connect tls/robot1.local:7447
  emos run --secure ~/emos-keys point_navigation                   # on robot1
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    sub = parser.add_subparsers(dest="action", required=True)
    p = sub.add_parser("create-keystore", help="create a keystore holding a new certificate authority (refuses to overwrite)")
    p.add_argument("dir", help="the keystore directory (must not exist, or be empty)")
    p.add_argument("--days", type=int, default=None, help="CA validity in days (default 3650)")
    p = sub.add_parser("create-identity", help="create a certificate and key for a robot, host or operator, signed by the CA")
    p.add_argument("dir", help="the keystore directory")
    p.add_argument("name", help="the identity's name: its certificate's common name, which access rules match")
    p.add_argument("--host", action="append", default=[], metavar="HOST",
                   help="a DNS name or IP address the identity is reached at (repeatable; localhost and 127.0.0.1 are always added)")
    p.add_argument("--days", type=int, default=None, help="validity in days (default 365)")
    p = sub.add_parser("policy", help="derive Zenoh access rules and TLS configuration from a recipe, one file per identity")
    p.add_argument("recipe", help="recipe name (see `emos ls`) or path of the recipe script")
    p.add_argument("--keystore", required=True, help="the keystore holding the identities")
    p.add_argument("--identity", action="append", required=True, metavar="NAME", help="a robot identity that runs the recipe (repeatable)")
    p.add_argument("--operator", action="append", default=[], metavar="NAME",
                   help="may publish the recipe's external inputs, subscribe, call services (repeatable)")
    p.add_argument("--viewer", action="append", default=[], metavar="NAME", help="may subscribe only (repeatable)")
    p.add_argument("--group", default=None, help="Zenoh group (default $EMOS_NET_GROUP, else 'default')")
    p.add_argument("--listen", action="append", default=None, metavar="ENDPOINT", help="robots listen here (default tls/0.0.0.0:7447)")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="every identity connects here (repeatable)")
    p.add_argument("--no-verify-name", action="store_true", help="do not check that a listener's certificate names the address dialled")
    p.add_argument("-o", "--output", default=None, help="output directory (default KEYSTORE/policies/<recipe>/)")
    p.add_argument("--force", action="store_true", help="replace existing files (they may hold hand edits)")


def run(args: argparse.Namespace) -> int:
    from emos.errors import ConfigError
    from emos.security.keystore import KeystoreError

    try:
        return _run(args)
    except (KeystoreError, ConfigError) as exc:
        print(f"emos security {args.action}: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    from emos.security import keystore as ks

    if args.action == "create-keystore":
        ca = ks.create_keystore(args.dir, days=args.days or ks.CA_DAYS)
        print(f"keystore {Path(args.dir).absolute()}: CA certificate {ca} (its key stays in {ca.parent}, mode 0600)")
        return 0
    if args.action == "create-identity":
        hosts = [*args.host, "localhost", "127.0.0.1"]
        cert, key = ks.create_identity(args.dir, args.name, hosts=hosts, days=args.days or ks.IDENTITY_DAYS)
        print(f"identity {args.name}: certificate {cert}, key {key}")
        return 0
    return _policy(args)


def _policy(args: argparse.Namespace) -> int:
    from emos.security.policy import Roles, policy_dir, write_policies
    from emos.security.recipe_graph import load_recipe_graph
    from emos.supervisor.recipes import RecipeNotFound, resolve_recipe
    from emos.transport.zenoh_net import net_group

    try:
        path = resolve_recipe(args.recipe)
    except RecipeNotFound as exc:
        print(f"emos security policy: {exc}", file=sys.stderr)
        return 2
    from emos.security.keystore import load_identity

    roles = Roles(robots=args.identity, operators=args.operator, viewers=args.viewer)
    for name in roles.all():  # before running the recipe: a missing or expired identity fails at once
        load_identity(args.keystore, name)
    if args.group is not None:
        os.environ["EMOS_NET_GROUP"] = args.group  # this process only: checked the way a run checks it
    try:
        group = net_group()
    except ValueError as exc:
        print(f"emos security policy: --group: {exc}", file=sys.stderr)
        return 2
    try:
        graph = load_recipe_graph(path)
    except Exception as exc:  # noqa: BLE001 - the recipe's own code: say where, then stop
        import traceback

        where = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename == str(path)]
        at = f" (line {where[-1].lineno}: {where[-1].line})" if where else ""
        print(f"emos security policy: recipe {path} raised {type(exc).__name__}: {exc}{at} before Launcher.bringup(); "
              "no policy written", file=sys.stderr)
        return 2
    out = Path(args.output) if args.output else policy_dir(args.keystore, path)
    written = write_policies(graph, roles, args.keystore, group, out, listen=args.listen or ["tls/0.0.0.0:7447"],
                             connect=args.connect, verify_name=not args.no_verify_name, force=args.force)
    print(f"recipe {path}: {len(graph.components)} components, {len(graph.outputs)} published topics, "
          f"{len(graph.external_inputs)} external inputs ({', '.join(graph.external_inputs) or 'none'}), {len(graph.services)} services")
    for note in graph.notes:
        print(f"  note: {note}", file=sys.stderr)
    for p in written:
        print(f"  wrote {p}")
    print(f"run it with: emos run --secure {args.keystore} {args.recipe}" + (f" --identity {args.identity[0]}" if len(args.identity) > 1 else ""))
    return 0


def secure_run_options(keystore: str, identity: str | None, zenoh_config: str | None, recipe: Path) -> str | None:
    """``emos run --secure KEYSTORE [--identity NAME] [--zenoh FILE]``: export the checked
    configuration to the run and start its security watch; an error message, or None."""
    from emos.security.keystore import KeystoreError
    from emos.security.secure_run import start_watch, use_secure

    try:
        path = use_secure(keystore, identity=identity, config=zenoh_config, recipe=recipe)
    except KeystoreError as exc:
        return f"--secure: {exc}"
    print(f"emos run: secure Zenoh (mutual TLS, access rules) with {path}", file=sys.stderr)
    if os.environ.get("EMOS_SECURITY_WATCH", "1") != "0":
        import atexit

        watch = start_watch(path)

        def stop() -> None:
            watch.terminate()
            try:
                watch.wait(timeout=5)
            except Exception:  # noqa: BLE001 - subprocess.TimeoutExpired
                watch.kill()
                watch.wait()

        atexit.register(stop)
    return None

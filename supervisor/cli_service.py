"""``emos service create|remove|status RECIPE``: a recipe as a systemd service.

``create`` writes a unit that runs the recipe with ``emos run`` (so each start keeps its log),
restarts it when it fails (``Restart=on-failure``: a supervisor that gave up exits 3), and
stops it the way the supervisor expects: SIGTERM to the launcher only, which stops the
components in reverse order, and SIGKILL for what is left after ``TimeoutStopSec``. Where
systemd runs and the unit folder is writable, the unit is installed, and enabled and started
unless ``--no-enable``; elsewhere it is printed with the commands to install it.
"""
from __future__ import annotations

import argparse
import getpass
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from emos.supervisor.recipes import ENV_HOME, RecipeNotFound, resolve_recipe

EXAMPLES = """examples:
  sudo emos service create ui_demo                          # /etc/systemd/system/emos-ui_demo.service, enabled and started
  emos service create ~/robot/patrol.py --name patrol --restart-time 5s --no-enable
  emos service create ui_demo --print                       # only show the unit
  emos service status ui_demo
  sudo emos service remove ui_demo
"""

_NAME = re.compile(r"^[A-Za-z0-9_.@-]+$")
_TIME = re.compile(r"^\d+(\.\d+)?(ms|s|min|h)?$")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    parser.add_argument("action", choices=("create", "remove", "status"))
    parser.add_argument("recipe", help="recipe name (see `emos ls`) or path of a recipe script; for remove and status, the recipe or the service name")
    parser.add_argument("--name", help="service name without .service (default: emos-<recipe>)")
    parser.add_argument("--service-description", default=None, help="the unit's Description (default: EMOS recipe <name>)")
    parser.add_argument("--install-path", default="/etc/systemd/system", help="folder of the unit file (default: %(default)s)")
    parser.add_argument("--restart-time", default="3s", help="wait before a restart after a failure, e.g. 3s (default: %(default)s)")
    parser.add_argument("--no-enable", action="store_true", help="write the unit but do not enable or start it")
    parser.add_argument("--user", default=None, help="run as this user (default: the user running this command, unless root)")
    parser.add_argument("--print", action="store_true", help="print the unit instead of installing it")


def systemd_running() -> bool:
    return Path("/run/systemd/system").is_dir() and shutil.which("systemctl") is not None


def _service_name(args: argparse.Namespace, recipe: Path | None) -> str:
    if args.name:
        name = args.name[:-8] if args.name.endswith(".service") else args.name
    else:
        stem = args.recipe if recipe is None else (recipe.parent.name if recipe.name == "recipe.py" else recipe.stem)
        name = "emos-" + re.sub(r"[^A-Za-z0-9_.-]", "_", Path(stem).stem if recipe is None else stem)
    if not _NAME.match(name):
        raise ValueError(f"service name {name!r} may only contain letters, digits and _ . @ -")
    return name


def unit_text(recipe: Path, name: str, description: str, restart_time: str, user: str | None) -> str:
    command = [sys.executable, "-m", "emos.supervisor.cli", "run", str(recipe)]
    lines = [
        "[Unit]",
        f"Description={description}",
        "After=network-online.target",
        "Wants=network-online.target",
        "StartLimitIntervalSec=0",
        "",
        "[Service]",
        "Type=simple",
        f"ExecStart={shlex.join(command)}",
        f"WorkingDirectory={recipe.parent}",
        "Restart=on-failure",
        f"RestartSec={restart_time}",
        "KillMode=mixed",
        "TimeoutStopSec=30",
        "Environment=PYTHONUNBUFFERED=1",
    ]
    if os.environ.get(ENV_HOME):
        lines.append(f"Environment={ENV_HOME}={os.environ[ENV_HOME]}")
    if user:
        lines.append(f"User={user}")
    lines += ["", "[Install]", "WantedBy=multi-user.target", ""]
    return "\n".join(lines)


def _systemctl(*words: str) -> int:
    print(f"  $ systemctl {' '.join(words)}", flush=True)
    return subprocess.run(["systemctl", *words]).returncode


def run(args: argparse.Namespace) -> int:
    if not _TIME.match(args.restart_time):
        print(f"emos service: --restart-time must be a duration such as 3s or 500ms, got {args.restart_time!r}", file=sys.stderr)
        return 2
    recipe: Path | None = None
    try:
        recipe = resolve_recipe(args.recipe).resolve()
    except RecipeNotFound as exc:
        if args.action == "create":
            print(f"emos service: {exc}", file=sys.stderr)
            return 2
    try:
        name = _service_name(args, recipe)
    except ValueError as exc:
        print(f"emos service: {exc}", file=sys.stderr)
        return 2
    unit_path = Path(args.install_path) / f"{name}.service"
    if args.action == "status":
        print(f"unit file: {unit_path} ({'present' if unit_path.exists() else 'absent'})")
        if systemd_running():
            return _systemctl("status", "--no-pager", f"{name}.service")
        print("systemd is not running on this machine: no live status")
        return 0 if unit_path.exists() else 3
    if args.action == "remove":
        if systemd_running():
            _systemctl("disable", "--now", f"{name}.service")
        if unit_path.exists():
            unit_path.unlink()
            print(f"removed {unit_path}")
        else:
            print(f"no unit file {unit_path}")
        if systemd_running():
            _systemctl("daemon-reload")
        return 0
    assert recipe is not None
    user = args.user if args.user is not None else (None if os.geteuid() == 0 else getpass.getuser())
    text = unit_text(recipe, name, args.service_description or f"EMOS recipe {recipe.parent.name if recipe.name == 'recipe.py' else recipe.stem}",
                     args.restart_time, user)
    if args.print:
        print(text, end="")
        return 0
    try:
        unit_path.parent.mkdir(parents=True, exist_ok=True)
        unit_path.write_text(text)
    except OSError as exc:
        print(f"emos service: cannot write {unit_path}: {exc.strerror or exc} (run with sudo, or --install-path)", file=sys.stderr)
        print(f"the unit would be:\n\n{text}", file=sys.stderr)
        return 1
    print(f"[1/3] wrote {unit_path}")
    if not systemd_running():
        print("[2/3] systemd is not running here: install the unit on the robot with\n"
              f"  sudo cp {unit_path} /etc/systemd/system/ && sudo systemctl daemon-reload && sudo systemctl enable --now {name}.service")
        return 0
    if _systemctl("daemon-reload") != 0:
        return 1
    print("[2/3] systemd reloaded")
    if args.no_enable:
        print(f"[3/3] not enabled (--no-enable); start it with: sudo systemctl enable --now {name}.service")
        return 0
    code = _systemctl("enable", "--now", f"{name}.service")
    print(f"[3/3] {'enabled and started' if code == 0 else 'enabling failed'}: {name}.service (logs: emos logs, journalctl -u {name})")
    return code

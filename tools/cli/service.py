"""``emos service create|remove|status RECIPE``: a recipe as a systemd service; and
``emos service call|list``: the services of a running system's components (:mod:`.service_call`).

``create`` writes a unit that runs the recipe with ``emos run`` (so each start keeps its log),
restarts it when it fails (``Restart=on-failure``: a supervisor that gave up exits 3), and
stops it the way the supervisor expects: SIGTERM to the launcher only, which stops the
components in reverse order, and SIGKILL for what is left after ``TimeoutStopSec``. Where
systemd runs and the unit folder is writable, the unit is installed, and enabled and started
unless ``--no-enable``; elsewhere it is printed with the commands to install it.

The unit usually runs as root, so nothing the user typed may change its meaning. Every value
is checked (no control characters: a newline would start a directive of its own, such as
``ExecStartPre=``) and written the way systemd reads it back: ``%`` doubled wherever systemd
expands specifiers, ``$`` doubled in ``ExecStart=`` arguments, and words with spaces or quotes
quoted with backslash escapes. Before ``create`` reports success the written unit is verified:
by ``systemd-analyze verify`` where that exists, and always by the strict reader below, which
parses the unit back with systemd's rules and requires every value to come out as intended.
A unit that fails either check is removed.
"""
from __future__ import annotations

import argparse
import os
import pwd
import re
import shutil
import subprocess
import sys
from pathlib import Path

from emos.errors import EmosError
from emos.supervisor.recipes import ENV_HOME, RecipeNotFound, resolve_recipe
from emos.tools.cli.common import add_run_argument, options_anywhere

EXAMPLES = """examples:
  emos service call planner save_plan_to_file '{"file_location": "/tmp", "file_name": "path.csv"}'
  emos service list planner                                 # its services with request -> response types
  sudo emos service create ui_demo                          # /etc/systemd/system/emos-ui_demo.service, enabled and started
  emos service create ~/robot/patrol.py --name patrol --restart-time 5s --no-enable
  emos service create ui_demo --print                       # only show the unit
  emos service status ui_demo
  sudo emos service remove ui_demo
"""

_NAME = re.compile(r"^[A-Za-z0-9_.@-]+$")
_TIME = re.compile(r"^\d+(\.\d+)?(ms|s|min|h)?$")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
# A portable user name (POSIX, as useradd accepts it); systemd's own rule is looser, ours must
# also stay clear of the characters the unit file gives meaning to (% $ quotes, spaces).
_USER = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]{0,31}$")
# ExecStart words made only of these need no quotes (";" alone would separate two commands).
_PLAIN_WORD = re.compile(r"^[A-Za-z0-9_@%+=:,./$-]+$")
_VERIFY_TIMEOUT_S = 60.0  # bounds a hung systemd-analyze; it answers in milliseconds


class UnitError(EmosError, ValueError):
    """A value that cannot be written into a systemd unit as given."""


def _unit_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--name", help="service name without .service (default: emos-<recipe>)")
    parser.add_argument("--service-description", default=None, help="the unit's Description (default: EMOS recipe <name>)")
    parser.add_argument("--install-path", default="/etc/systemd/system", help="folder of the unit file (default: %(default)s)")
    parser.add_argument("--restart-time", default="3s", help="wait before a restart after a failure, e.g. 3s (default: %(default)s)")
    parser.add_argument("--no-enable", action="store_true", help="write the unit but do not enable or start it")
    parser.add_argument("--user", default=None, help="run as this existing user (default: the user running this command, unless root)")
    parser.add_argument("--print", action="store_true", help="print the unit instead of installing it")


def _call_options(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for an answer (default %(default)s)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from emos.tools.cli import service_call

    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    sub = parser.add_subparsers(dest="action", required=True, metavar="{create,remove,status,call,list}")
    units = []
    for verb, help_text in (("create", "write (and install, enable, start) the unit of a recipe"),
                            ("remove", "disable and remove the unit"), ("status", "the unit file and its systemd status")):
        p = sub.add_parser(verb, help=help_text, description=help_text)
        p.add_argument("recipe", help="recipe name (see `emos ls`) or path of a recipe script; for remove and status, the recipe or the service name")
        units.append(p)
    call = sub.add_parser("call", help="call a service of a component of the running system (as `ros2 service call`)",
                          description="call a service of a component of the running system, print the response as JSON")
    service_call.add_call_arguments(call)
    listed = sub.add_parser("list", help="the services of a component (or of all) with their types (as `ros2 service list -t`)")
    service_call.add_list_arguments(listed)
    # Every option before or after the verb: the unit options with the unit verbs, --run with call and list.
    options_anywhere(parser, units, _unit_options)
    options_anywhere(parser, [call, listed], _call_options)


def systemd_running() -> bool:
    return Path("/run/systemd/system").is_dir() and shutil.which("systemctl") is not None


# ---------------------------------------------------------------------------------- checking input
def check_text(what: str, value: str) -> str:
    """``value`` if it can go into a unit file line; else UnitError naming ``what``."""
    bad = _CONTROL.search(value)
    if bad:
        raise UnitError(f"{what} must not contain control characters (newline, tab, ...): "
                        f"found {bad.group()!r} in {value!r}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise UnitError(f"{what} is not valid UTF-8 text: {value!r}") from None
    return value


def check_user(user: str) -> str:
    check_text("--user", user)
    if not _USER.match(user):
        raise UnitError(f"--user must be a user name (a letter or _, then letters, digits, _ . -; at most 32), got {user!r}")
    try:
        pwd.getpwnam(user)
    except KeyError:
        raise UnitError(f"--user {user!r}: no such user on this machine") from None
    return user


def _service_name(args: argparse.Namespace, recipe: Path | None) -> str:
    if args.name:
        name = args.name.removesuffix(".service")
    else:
        stem = args.recipe if recipe is None else (recipe.parent.name if recipe.name == "recipe.py" else recipe.stem)
        name = "emos-" + re.sub(r"[^A-Za-z0-9_.-]", "_", Path(stem).stem if recipe is None else stem)
    if not _NAME.match(name):
        raise ValueError(f"service name {name!r} may only contain letters, digits and _ . @ -")
    return name


# ---------------------------------------------------------------------------------- writing
def _no_specifiers(value: str) -> str:
    """``value`` where systemd expands specifiers (``%n``, ``%h``...): each ``%`` doubled."""
    return value.replace("%", "%%")


def _quoted(value: str) -> str:
    """A double-quoted word as systemd unquotes it (C-style backslash escapes)."""
    return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'


def exec_line(argv: list[str]) -> str:
    """The ``ExecStart=`` value that runs exactly ``argv``.

    systemd expands specifiers in each word, unquotes it, and at start replaces ``$NAME`` and
    ``${NAME}`` in the arguments by environment variables (``$$`` is a ``$``).
    """
    program = argv[0]
    if not program.startswith("/"):
        raise UnitError(f"the program of ExecStart must be an absolute path, got {program!r}")
    if "$" in program:
        # systemd takes the program path literally but expands argv[0]: no escaping fits both.
        raise UnitError(f"the Python interpreter path {program!r} contains '$', which systemd cannot run unambiguously")
    words = []
    for i, word in enumerate(argv):
        word = _no_specifiers(word) if i == 0 else _no_specifiers(word).replace("$", "$$")
        words.append(word if _PLAIN_WORD.match(word) else _quoted(word))
    return " ".join(words)


def environment_line(key: str, value: str) -> str:
    """An ``Environment=`` value: one quoted ``KEY=value`` word (systemd unquotes, then expands
    specifiers), so spaces and quotes in ``value`` stay in it."""
    return _quoted(f"{key}={_no_specifiers(value)}")


def intended(recipe: Path, description: str, restart_time: str, user: str | None) -> dict:
    """What the unit must say, as systemd should read it back (see :func:`read_unit`)."""
    env = {"PYTHONUNBUFFERED": "1"}
    home = os.environ.get(ENV_HOME)
    if home:
        env[ENV_HOME] = check_text(f"${ENV_HOME}", home)
    description = description.strip()  # systemd strips what surrounds a value
    for what, value in (("--service-description", description), ("the recipe folder", str(recipe.parent))):
        if _continues(value):
            raise UnitError(f"{what} must not end with a backslash (systemd would join the next line to it): {value!r}")
    return {
        "description": description,
        "argv": [sys.executable, "-m", "emos", "run", str(recipe)],  # the stable entry point, wherever the CLI lives
        "working_directory": str(recipe.parent),
        "restart_time": restart_time,
        "environment": env,
        "user": user,
    }


def unit_text(want: dict) -> str:
    lines = [
        "[Unit]",
        f"Description={_no_specifiers(want['description'])}",
        "After=network-online.target",
        "Wants=network-online.target",
        "StartLimitIntervalSec=0",
        "",
        "[Service]",
        "Type=simple",
        f"ExecStart={exec_line(want['argv'])}",
        f"WorkingDirectory={_no_specifiers(want['working_directory'])}",
        "Restart=on-failure",
        f"RestartSec={want['restart_time']}",
        "KillMode=mixed",
        "TimeoutStopSec=30",
    ]
    lines += [f"Environment={environment_line(k, v)}" for k, v in want["environment"].items()]
    if want["user"]:
        lines.append(f"User={want['user']}")
    lines += ["", "[Install]", "WantedBy=multi-user.target", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- reading back
_SECTIONS = {
    "Unit": {"Description", "After", "Wants", "StartLimitIntervalSec"},
    "Service": {"Type", "ExecStart", "WorkingDirectory", "Restart", "RestartSec", "KillMode", "TimeoutStopSec", "Environment", "User"},
    "Install": {"WantedBy"},
}
_REPEATABLE = {"Environment"}
_ESCAPES = {"\\": "\\", '"': '"', "'": "'", "n": "\n", "t": "\t", "r": "\r", "s": " ", " ": " ", ";": ";"}


def _continues(line: str) -> bool:
    """Whether systemd joins ``line`` to the next one: it ends in an odd number of backslashes."""
    return (len(line) - len(line.rstrip("\\"))) % 2 == 1


def _expand_specifiers(value: str, where: str) -> str:
    """``%%`` -> ``%``; any other specifier is an error here (we never write one)."""
    out, i = [], 0
    while i < len(value):
        if value[i] == "%":
            if value[i + 1 : i + 2] != "%":
                raise UnitError(f"{where}: unescaped specifier {value[i:i + 2]!r} in {value!r}")
            i += 1
        out.append(value[i])
        i += 1
    return "".join(out)


def split_words(value: str, where: str) -> list[str]:
    """Words as systemd's ``extract_first_word(UNQUOTE|CUNESCAPE)`` splits them (our subset of
    escapes; any other is an error)."""
    words: list[str] = []
    i, n = 0, len(value)
    while True:
        while i < n and value[i] in " \t":
            i += 1
        if i >= n:
            return words
        word: list[str] = []
        quote = ""
        while i < n:
            ch = value[i]
            if ch == "\\":
                if i + 1 >= n or value[i + 1] not in _ESCAPES:
                    raise UnitError(f"{where}: unsupported escape {value[i:i + 2]!r} in {value!r}")
                word.append(_ESCAPES[value[i + 1]])
                i += 2
                continue
            if quote:
                if ch == quote:
                    quote = ""
                else:
                    word.append(ch)
            elif ch in "\"'":
                quote = ch
            elif ch in " \t":
                break
            else:
                word.append(ch)
            i += 1
        if quote:
            raise UnitError(f"{where}: unterminated quote in {value!r}")
        words.append("".join(word))


def _expand_dollars(word: str, where: str) -> str:
    """``$$`` -> ``$``; a lone ``$`` would be replaced by an environment variable at start."""
    if any(len(run) % 2 for run in re.findall(r"\$+", word)):
        raise UnitError(f"{where}: {word!r} holds a '$' systemd would expand")
    return word.replace("$$", "$")


def read_unit(text: str) -> dict[str, dict[str, list[str]]]:
    """The unit as ``{section: {key: [raw values]}}``, read strictly: every line is a section
    header, blank, or ``Key=value`` with a key we write in that section; no comments, no
    continuation lines, no key twice (but ``Environment``)."""
    sections: dict[str, dict[str, list[str]]] = {}
    section, current = "", None
    for number, line in enumerate(text.split("\n"), 1):
        where = f"unit line {number}"
        if _CONTROL.search(line):
            raise UnitError(f"{where}: control character in {line!r}")
        if not line.strip():
            continue
        if _continues(line):
            raise UnitError(f"{where}: ends with a backslash, which joins it to the next line: {line!r}")
        if line.startswith("["):
            name = line[1:-1] if line.endswith("]") else ""
            if name not in _SECTIONS or name in sections:
                raise UnitError(f"{where}: unexpected section header {line!r}")
            section, current = name, sections.setdefault(name, {})
            continue
        key, sep, value = line.partition("=")
        if not sep or current is None:
            raise UnitError(f"{where}: not Key=value inside a section: {line!r}")
        if key not in _SECTIONS[section]:
            raise UnitError(f"{where}: unexpected key {key!r} in [{section}]")
        if key in current and key not in _REPEATABLE:
            raise UnitError(f"{where}: {key} given twice")
        current.setdefault(key, []).append(value.strip())
    return sections


def check_unit(text: str, want: dict) -> None:
    """Raise UnitError unless ``text`` reads back (systemd's rules) as exactly ``want``."""
    unit = read_unit(text)
    service = unit.get("Service", {})

    def one(section: dict, key: str) -> str | None:
        values = section.get(key)
        return values[0] if values else None

    description = one(unit.get("Unit", {}), "Description")
    if description is None or _expand_specifiers(description, "Description") != want["description"]:
        raise UnitError(f"Description reads back as {description!r}, not {want['description']!r}")
    words = split_words(one(service, "ExecStart") or "", "ExecStart")
    argv = [_expand_specifiers(w, "ExecStart") for w in words]
    argv = argv[:1] + [_expand_dollars(w, "ExecStart") for w in argv[1:]]
    if argv != want["argv"]:
        raise UnitError(f"ExecStart reads back as {argv!r}, not {want['argv']!r}")
    workdir = one(service, "WorkingDirectory")
    if workdir is None or _expand_specifiers(workdir, "WorkingDirectory") != want["working_directory"]:
        raise UnitError(f"WorkingDirectory reads back as {workdir!r}, not {want['working_directory']!r}")
    env: dict[str, str] = {}
    for value in service.get("Environment", []):
        for word in split_words(value, "Environment"):
            key, sep, val = _expand_specifiers(word, "Environment").partition("=")
            if not sep:
                raise UnitError(f"Environment: {word!r} is not KEY=value")
            env[key] = val
    if env != want["environment"]:
        raise UnitError(f"Environment reads back as {env!r}, not {want['environment']!r}")
    if one(service, "User") != want["user"]:
        raise UnitError(f"User reads back as {one(service, 'User')!r}, not {want['user']!r}")
    if one(service, "RestartSec") != want["restart_time"]:
        raise UnitError(f"RestartSec reads back as {one(service, 'RestartSec')!r}, not {want['restart_time']!r}")


def verify_with_systemd(unit_path: Path) -> str | None:
    """Problems ``systemd-analyze verify`` finds in the unit file ('' if none), or None when
    the tool is not installed. Warnings about our own file count: systemd ignores such a line
    (and e.g. falls back to a default) instead of refusing the unit."""
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        return None
    try:
        out = subprocess.run([analyze, "verify", "--man=no", str(unit_path)], check=False, capture_output=True, text=True,
                             timeout=_VERIFY_TIMEOUT_S, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return f"systemd-analyze verify did not answer within {_VERIFY_TIMEOUT_S:g} s"
    except OSError as exc:
        return f"systemd-analyze could not run: {exc}"
    ours = [line for line in (out.stdout + out.stderr).splitlines() if line.startswith(f"{unit_path}:") or unit_path.name in line]
    if out.returncode != 0 or ours:
        return "\n".join(ours or (out.stdout + out.stderr).strip().splitlines() or [f"exit code {out.returncode}"])
    return ""


# ---------------------------------------------------------------------------------- the command
def _systemctl(*words: str) -> int:
    print(f"  $ systemctl {' '.join(words)}", flush=True)
    return subprocess.run(["systemctl", *words], check=False).returncode


def _fail(message: str, code: int = 2) -> int:
    print(f"emos service: {message}", file=sys.stderr)
    return code


def _default_user() -> str | None:
    """The user running this command, unless root (a root service needs no User=). From the
    password database, not $USER or $LOGNAME, which the caller's environment can say anything in."""
    if os.geteuid() == 0:
        return None
    return pwd.getpwuid(os.geteuid()).pw_name


def run(args: argparse.Namespace) -> int:
    if args.action in ("call", "list"):
        from emos.tools.cli import service_call

        return service_call.run_call(args) if args.action == "call" else service_call.run_list(args)
    try:
        for option, value in (("RECIPE", args.recipe), ("--name", args.name), ("--service-description", args.service_description),
                              ("--install-path", args.install_path), ("--restart-time", args.restart_time), ("--user", args.user)):
            if value is not None:
                check_text(option, value)
    except UnitError as exc:
        return _fail(str(exc))
    if not _TIME.match(args.restart_time):
        return _fail(f"--restart-time must be a duration such as 3s or 500ms, got {args.restart_time!r}")
    recipe: Path | None = None
    try:
        recipe = resolve_recipe(args.recipe).resolve()
    except RecipeNotFound as exc:
        if args.action == "create":
            return _fail(str(exc))
    try:
        name = _service_name(args, recipe)
    except ValueError as exc:
        return _fail(str(exc))
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
    try:
        check_text("the recipe path", str(recipe))
        user = check_user(args.user) if args.user is not None else _default_user()
        default_description = f"EMOS recipe {recipe.parent.name if recipe.name == 'recipe.py' else recipe.stem}"
        want = intended(recipe, check_text("the recipe name", default_description) if args.service_description is None
                        else args.service_description, args.restart_time, user)
        text = unit_text(want)
        check_unit(text, want)
    except UnitError as exc:
        return _fail(str(exc))
    if args.print:
        print(text, end="")
        return 0
    try:
        previous = unit_path.read_bytes() if unit_path.is_file() else None
        unit_path.parent.mkdir(parents=True, exist_ok=True)
        unit_path.write_text(text)
    except OSError as exc:
        print(f"emos service: cannot write {unit_path}: {exc.strerror or exc} (run with sudo, or --install-path)", file=sys.stderr)
        print(f"the unit would be:\n\n{text}", file=sys.stderr)
        return 1
    problems = verify_with_systemd(unit_path)
    if problems:
        if previous is None:
            unit_path.unlink(missing_ok=True)
            undone = "it was removed again"
        else:
            unit_path.write_bytes(previous)
            undone = "the unit that was there before is back in place"
        return _fail(f"systemd-analyze verify rejects the unit {unit_path}, so {undone}; nothing was installed:\n{problems}", 1)
    checked = "systemd-analyze verify and the built-in reader" if problems is not None else \
        "the built-in reader (systemd-analyze is not installed: systemd's own check was skipped)"
    print(f"[1/3] wrote {unit_path} (checked by {checked})")
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

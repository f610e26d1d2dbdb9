"""``emos ui``: the web UI's paired devices and pairing code.

``emos ui tokens`` lists the device tokens of the running system's UI (name, role, status,
expiry; never the tokens: only their hashes are stored), ``emos ui revoke ID|NAME|all`` revokes
(open pages of the device are closed within a second), ``emos ui pair`` shows the current
single-use pairing code and its QR code.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from emos.tools.cli.common import add_run_argument, join_run, options_anywhere

STORE = "ui.devices.json"
PAIRING = "ui.pairing"


def _store_option(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("--store", metavar="FILE", default=None,
                        help="the device-token store, when the recipe keeps it elsewhere (UIConfig.token_store); "
                             "default: the running system's <run dir>/ui.devices.json")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = ("examples:\n  emos ui tokens\n  emos ui revoke 3f2a9c0b1d4e     # by id\n  emos ui revoke tablet           # every device so named\n"
                     "  emos ui revoke all\n  emos ui pair                    # the current pairing code and its QR code\n")
    sub = parser.add_subparsers(dest="verb", required=True)
    tokens = sub.add_parser("tokens", help="list the paired devices (id, name, role, status, expiry)")
    tokens.add_argument("--json", action="store_true", help="print JSON")
    revoke = sub.add_parser("revoke", help="revoke device tokens: an id, a device name, or 'all'")
    revoke.add_argument("which", help="device id, device name, or 'all'")
    pair = sub.add_parser("pair", help="show the current pairing code and its QR code")
    options_anywhere(parser, [tokens, revoke, pair], _store_option)


def _store_path(args: argparse.Namespace) -> Path:
    if args.store:
        return Path(args.store).expanduser()
    return Path(join_run(args.run).run_dir) / STORE


def _when(t: float | None) -> str:
    return time.strftime("%Y-%m-%d %H:%M", time.localtime(t)) if t else "-"


def run(args: argparse.Namespace) -> int:
    from emos.actors.ui.devices import DeviceStore, DeviceStoreError

    if args.verb == "pair":
        return _pair(args)
    store = DeviceStore(_store_path(args))
    try:
        if args.verb == "tokens":
            records = store.listing()
            if args.json:
                print(json.dumps(records, indent=1))
                return 0
            if not records:
                print(f"no paired devices ({store.path})")
                return 0
            print(f"{'ID':<13} {'NAME':<24} {'ROLE':<9} {'STATUS':<8} {'PAIRED':<17} EXPIRES")
            for r in records:
                print(f"{r['id']:<13} {str(r['name'])[:24]:<24} {r['role']:<9} {r['status']:<8} {_when(r['created']):<17} {_when(r['expires'])}")
            return 0
        revoked = store.revoke(args.which)
    except (DeviceStoreError, OSError) as exc:
        print(f"emos ui: {exc}", file=sys.stderr)
        return 1
    if not revoked:
        print(f"emos ui revoke: no active device token matches {args.which!r} (see `emos ui tokens`)", file=sys.stderr)
        return 1
    for r in revoked:
        print(f"revoked {r['id']} ({r['name']}, {r['role']})")
    return 0


def _pair(args: argparse.Namespace) -> int:
    from emos.actors.ui.pairing import terminal_qr, until_text

    path = Path(join_run(args.run).run_dir) / PAIRING
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        print(f"emos ui pair: no pairing code ({path} is missing): is the UI running, with pairing on?", file=sys.stderr)
        return 1
    except (OSError, ValueError) as exc:
        print(f"emos ui pair: cannot read {path}: {exc}", file=sys.stderr)
        return 1
    expires = data.get("expires")
    until = f", valid until {until_text(expires)}" if isinstance(expires, (int, float)) else ""
    print(f"pairing code {data.get('code')} (single use{until}; devices get the role {data.get('role')})")
    if data.get("url"):
        print(f"or open {data['url']}")
        print(terminal_qr(data["url"]))
    return 0

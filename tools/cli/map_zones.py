"""``emos map zones MAP.yaml VERB``: keepout and speed-limit zones of a map, as filter masks.

The zones of ``office.yaml`` live in two ROS-style masks beside it (map_server YAML + PGM that
Nav2's costmap filters and the Planner's ``costmap.keepout_mask`` / ``costmap.speed_mask`` read):
``office_keepout.yaml`` and ``office_speed.yaml``. Each mask YAML also lists its zones by name,
so they can be listed and edited:

    emos map zones office.yaml list
    emos map zones office.yaml add kitchen --kind keepout --polygon "1,1 3,1 3,2 1,2"
    emos map zones office.yaml add hall --kind speed --value 40 --polygon "0,0 2,0 2,1"
    emos map zones office.yaml set hall --value 30
    emos map zones office.yaml remove kitchen
    emos map zones office.yaml import zones.yaml     # a list of {name, kind, polygon, value}

Speed values are percent of the robot's maximum speed (``--speed-type percent``, the default)
or m/s (``--speed-type absolute``); values out of range are refused naming the zone. Zones are
drawn on the command line or in YAML here; the web UI edits the same masks (``enable_ui(zones_map=...)``,
docs/ui.md).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run", "mask_paths"]


def add_parser(sub: Any) -> None:
    """Add ``zones`` to the ``emos map`` verbs."""
    z = sub.add_parser("zones", help="list, add, edit, remove keepout and speed-limit zones (filter masks)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    z.add_argument("file", help="the map_server YAML the zones belong to")
    verbs = z.add_subparsers(dest="zones_verb", required=True)
    verbs.add_parser("list", help="print the zones")
    for verb, help_text in (("add", "add a zone"), ("set", "change a zone's polygon or value")):
        v = verbs.add_parser(verb, help=help_text)
        v.add_argument("name")
        v.add_argument("--kind", choices=("keepout", "speed"), required=verb == "add")
        v.add_argument("--polygon", required=verb == "add", help='"x,y x,y x,y ..." in metres, map frame')
        v.add_argument("--value", type=float, help="speed zones: the limit (percent, or m/s with --speed-type absolute)")
        v.add_argument("--speed-type", choices=("percent", "absolute"), help="speed mask type (default: the mask's, else percent)")
    r = verbs.add_parser("remove", help="remove a zone")
    r.add_argument("name")
    i = verbs.add_parser("import", help="add or replace zones from a YAML list of {name, kind, polygon, value}")
    i.add_argument("zones_file")
    i.add_argument("--speed-type", choices=("percent", "absolute"))


def mask_paths(map_yaml: Path) -> dict[str, Path]:
    from emos.actors.nav.costmap.mask_io import zone_mask_paths

    return zone_mask_paths(map_yaml)


def _polygon(text: str) -> list[list[float]]:
    try:
        return [[float(c) for c in point.split(",")] for point in text.split()]
    except ValueError:
        raise ValueError(f"--polygon: expected \"x,y x,y x,y ...\" (metres), got {text!r}") from None


def _load(map_yaml: Path) -> tuple[list[Any], str]:
    from emos.actors.nav.costmap.mask_io import load_zones

    return load_zones(map_yaml)


def _save(map_yaml: Path, zones: list[Any], speed_type: str) -> list[Path]:
    from emos.actors.nav.costmap.mask_io import save_zones

    return save_zones(map_yaml, zones, speed_type)


def edit(args: argparse.Namespace) -> str:
    """Apply one verb; returns what to print. Raises ValueError (or MapFileError) naming the problem."""
    import yaml

    from emos.actors.nav.costmap import zone_from_dict

    map_yaml = Path(args.file)
    zones, speed_type = _load(map_yaml)
    if getattr(args, "speed_type", None):
        speed_type = f"speed_{args.speed_type}"
    by_name = {z.name: z for z in zones}
    verb = args.zones_verb
    if verb == "list":
        if not zones:
            return f"{map_yaml}: no zones"
        unit = "%" if speed_type == "speed_percent" else " m/s"
        return "\n".join(f"{z.name:20s} {z.kind:8s}" + (f" {z.value:g}{unit}" if z.kind == "speed" else "")
                         + "  " + " ".join(f"{x:g},{y:g}" for x, y in z.polygon) for z in zones)
    if verb == "remove":
        if args.name not in by_name:
            raise ValueError(f"no zone named {args.name!r} in {map_yaml}'s masks; zones: {', '.join(by_name) or 'none'}")
        del by_name[args.name]
    elif verb in ("add", "set"):
        if verb == "add" and args.name in by_name:
            raise ValueError(f"zone {args.name!r} already exists in {map_yaml}'s masks (use `set` to change it)")
        if verb == "set" and args.name not in by_name:
            raise ValueError(f"no zone named {args.name!r} in {map_yaml}'s masks; zones: {', '.join(by_name) or 'none'}")
        doc = by_name[args.name].to_dict() if verb == "set" else {"name": args.name}
        if args.kind:
            doc["kind"] = args.kind
        if args.polygon:
            doc["polygon"] = _polygon(args.polygon)
        if args.value is not None:
            doc["value"] = args.value
        if doc.get("kind") == "speed" and "value" not in doc:
            raise ValueError(f"speed zone {args.name!r} needs --value")
        by_name[args.name] = zone_from_dict(doc, "command line")
    elif verb == "import":
        source = Path(args.zones_file)
        items = yaml.safe_load(source.read_text())
        items = items.get("zones", items) if isinstance(items, dict) else items
        if not isinstance(items, list):
            raise ValueError(f"{source}: expected a list of zones (name, kind, polygon, value)")
        for item in items:
            zone = zone_from_dict(item, str(source))
            by_name[zone.name] = zone
    written = _save(map_yaml, list(by_name.values()), speed_type)
    return "\n".join(str(p) for p in written) or "no zones: nothing written"


def run(args: argparse.Namespace) -> int:
    from emos.actors.nav.maps import MapFileError

    try:
        print(edit(args))
    except (MapFileError, ValueError, OSError) as exc:
        print(f"emos map zones: {exc}", file=sys.stderr)
        return 2
    return 0

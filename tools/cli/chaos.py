"""``emos chaos``: break a running recipe on purpose and check that it recovers.

    emos chaos list                                   # nemeses and shipped scenarios
    emos chaos run sensor-kills --seed 1 --runs 3     # a shipped scenario, three seeded runs
    emos chaos run my_scenario.yaml --json            # your own scenario file
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = __doc__.split("\n\n", 1)[1]
    sub = parser.add_subparsers(dest="chaos_command", required=True)
    sub.add_parser("list", help="list nemeses and shipped scenarios")
    run = sub.add_parser("run", help="run a scenario (a shipped name or a YAML file)")
    run.add_argument("scenario", help="shipped scenario name (see `emos chaos list`) or path of a scenario YAML file")
    run.add_argument("--seed", type=int, default=1, help="seed of the first run (run k uses seed + k)")
    run.add_argument("--runs", type=int, default=1, help="number of seeded runs")
    run.add_argument("--short", action="store_true", help="use the scenario's short settings (as the tests do)")
    run.add_argument("--out", default="chaos-out", help="folder for logs, histories and timeline pictures")
    run.add_argument("--json", action="store_true", help="print the aggregate result as JSON")
    run.add_argument("--no-plot", action="store_true", help="do not draw timeline pictures")


def run(args: argparse.Namespace) -> int:
    from emos.chaos.nemesis import CATALOGUE, NemesisError
    from emos.chaos.scenario import Scenario, ScenarioError, shipped_scenarios

    if args.chaos_command == "list":
        print("nemeses:")
        for kind, cls in sorted(CATALOGUE.items()):
            print(f"  {kind:<14} {cls.summary}")
        print("\nscenarios:")
        for name, path in shipped_scenarios().items():
            try:
                desc = Scenario.load(path).description
            except (ScenarioError, NemesisError) as exc:
                desc = f"(broken: {exc})"
            print(f"  {name:<18} {desc}")
        return 0
    if args.runs < 1:
        print("emos chaos run: --runs must be >= 1", file=sys.stderr)
        return 2
    try:
        scenario = Scenario.load(args.scenario, short=args.short)
    except (ScenarioError, NemesisError) as exc:
        print(f"emos chaos run: {exc}", file=sys.stderr)
        return 2
    from emos.chaos.report import aggregate, table, timeline_png
    from emos.chaos.scenario import run_scenario

    out = Path(args.out) / f"{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    results = []
    say = (lambda line: print(line, file=sys.stderr, flush=True)) if args.json else (lambda line: print(line, flush=True))
    try:
        for k in range(args.runs):
            result = run_scenario(scenario, args.seed + k, out, progress=say)
            if not args.no_plot:
                png = timeline_png(Path(result["history"]), result, out / f"timeline-{result['seed']}.png")
                result["timeline"] = str(png) if png else None
                if png is None:
                    say("timeline picture skipped: matplotlib is not installed (pip install 'emos[plots]')")
            results.append(result)
            say(f"[{scenario.name} seed {result['seed']}] {'pass' if result['passed'] else 'FAIL: ' + '; '.join(result['problems'])}")
    except (KeyboardInterrupt, SystemExit) as exc:  # Ctrl-C; SIGTERM raises SystemExit(143) (see cli.py)
        say("interrupted: nemeses undone, system stopped")
        if isinstance(exc, SystemExit):
            if results:  # keep what the finished runs found, then end as terminated
                (out / "results.json").write_text(json.dumps({"summary": aggregate(results), "runs": results}, indent=1, default=str))
                say(f"results of the {len(results)} finished run(s): {out / 'results.json'}")
            raise
        if not results:
            return 130
    except (ScenarioError, NemesisError) as exc:  # found only once the system runs, e.g. a target it does not have
        print(f"emos chaos run: {scenario.source}, seed {args.seed + len(results)}: {exc} (nemeses undone, system stopped)",
              file=sys.stderr)
        return 2
    summary = aggregate(results)
    (out / "results.json").write_text(json.dumps({"summary": summary, "runs": results}, indent=1, default=str))
    if args.json:
        print(json.dumps(summary))
    else:
        print()
        print(table(results))
        print()
        print(f"{summary['passed']}/{summary['runs']} runs passed; faults {summary['faults']}, recovered {summary['recovered']}; "
              f"recovery p50 {summary['recover_ms']['p50']} ms, p95 {summary['recover_ms']['p95']} ms; leaks {summary['leaks']}; "
              f"details in {out}")
    return 0 if summary["passed"] == summary["runs"] else 1

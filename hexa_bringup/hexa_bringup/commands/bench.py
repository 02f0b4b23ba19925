"""`hexa bench`: run registered benchmarks, print a table and optionally JSON."""
from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run benchmarks; print a table (and JSON with --json)")
    p.add_argument("areas", nargs="*", help="areas to run (default: all)")
    p.add_argument("--quick", action="store_true", help="shorter runs (less precise)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.add_argument("--out", help="also write the JSON to this file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hexa.benchmarks import discover

    registry = discover()
    unknown = [a for a in args.areas if a not in registry]
    if unknown:
        raise SystemExit(f"hexa bench: unknown area(s) {unknown}; known: {sorted(registry)}")
    results: dict[str, list[dict]] = {}
    for area in args.areas or sorted(registry):
        rows = registry[area](args.quick)
        results[area] = [r.as_dict() for r in rows]
        if not args.json:
            print(f"\n## {area}")
            print(f"{'benchmark':44s} {'measured':>14s} {'unit':10s} {'target':16s} met")
            for r in rows:
                met = "-" if r.met is None else ("yes" if r.met else "NO")
                print(f"{r.name:44s} {r.value:14.4g} {r.unit:10s} {r.target:16s} {met}  {r.note}")
    text = json.dumps(results, indent=2)
    if args.json:
        print(text)
    else:
        print("\nJSON:")
        print(json.dumps(results))
    if args.out:
        with open(args.out, "w", encoding="utf-8") as f:
            f.write(text)
    return 0

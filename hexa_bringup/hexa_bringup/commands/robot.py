"""`hexa robot show {hexa|upsrpu}`: the robot description's geometry and parameters (SI units; mm/deg for humans)."""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
from typing import Any

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("robot", help="robot descriptions (geometry and parameters)",
                       description="Show a robot description loaded and validated from its YAML (SI units).")
    rsub = p.add_subparsers(dest="robot_command", metavar="ACTION")
    rsub.required = True
    show = rsub.add_parser("show", help="print geometry and parameters")
    show.add_argument("robot", choices=("hexa", "upsrpu"))
    show.add_argument("--description", help="robot description YAML (default: the packaged one)")
    show.add_argument("--json", action="store_true", help="print JSON (SI units)")
    show.set_defaults(func=run)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return value


def describe(robot: str, path: str | None = None) -> dict[str, Any]:
    """The description of `robot` as JSON-able data (SI units).

    Raises:
        RobotDescriptionError: the YAML is missing or invalid (the key is named).
    """
    if robot == "hexa":
        from hexa.robots.hexa_description import load_hexa

        return load_hexa(path).as_dict()
    from hexa.robots.upsrpu_description import load_upsrpu

    desc = load_upsrpu(path)
    out = {f.name: _plain(getattr(desc, f.name)) for f in dataclasses.fields(desc) if not f.name.startswith("_")}
    out["kind"] = "upsrpu"
    return out


def _human_hexa(d: dict[str, Any]) -> str:
    mm = 1000.0
    lines = [f"Hexa (6-RUS) description: {d['path']}",
             f"  arm l_a = {d['l_a'] * mm:.1f} mm, rod l_d = {d['l_d'] * mm:.1f} mm, IK branch {d['branch']:+d}",
             f"  arm range zeta = [{math.degrees(d['zeta_min']):.1f}, {math.degrees(d['zeta_max']):.1f}] deg",
             "  home pose: x y z = " + " ".join(f"{v * mm:.1f}" for v in d["home_pose"][:3]) + " mm, "
             "alpha beta gamma = " + " ".join(f"{math.degrees(v):.1f}" for v in d["home_pose"][3:]) + " deg",
             "  chain  alpha(deg) sigma   A_i in base (mm)             C_i in plate (mm)"]
    for i in range(6):
        a, c = d["A"][i], d["C"][i]
        lines.append(f"  {i + 1:>5}  {math.degrees(d['alpha'][i]):>9.1f} {d['sigma'][i]:>+5.0f}   "
                     f"({a[0] * mm:7.1f} {a[1] * mm:7.1f} {a[2] * mm:6.1f})   "
                     f"({c[0] * mm:7.1f} {c[1] * mm:7.1f} {c[2] * mm:6.1f})")
    lines.append(f"  masses: plate {d['plate']['mass']} kg, arm {d['arm']['mass']} kg, rod {d['rod']['mass']} kg")
    lines.append(f"  servo: K_t = {d['K_t']} N·m/A, torque max {d['torque_max']} N·m, "
                 f"speed max {math.degrees(d['speed_max']):.0f} deg/s")
    if d["sections"]:
        lines.append("  other sections: " + ", ".join(d["sections"]))
    return "\n".join(lines)


def _human_generic(d: dict[str, Any]) -> str:
    lines = [f"3UPS+RPU description: {d.get('path')}"]
    for k, v in d.items():
        if k in ("path", "kind"):
            continue
        lines.append(f"  {k}: {json.dumps(v)}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from hexa.robots.schema import RobotDescriptionError

    try:
        d = describe(args.robot, args.description)
    except RobotDescriptionError as exc:
        raise SystemExit(f"hexa robot show: {exc}") from exc
    if args.json:
        print(json.dumps(d, indent=2))
    else:
        print(_human_hexa(d) if args.robot == "hexa" else _human_generic(d))
    return 0

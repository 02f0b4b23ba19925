"""`hexa doctor`: what a robot PC needs before `hexa bringup`, checked one line each — ROS middleware, the Fast DDS
profile and shared-memory files, domain and discovery range, the graph, serial ports, RealSense cameras, the firmware
images and the firmware the running driver talks to."""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path

OK, WARN, FAIL, INFO = "ok", "warn", "fail", "info"
#: USB vendor ids of Arduino boards and of the usual USB-serial chips of clones (CH340, FTDI, CP210x)
SERIAL_VENDORS = {0x2341: "Arduino", 0x2A03: "Arduino", 0x1A86: "CH340", 0x0403: "FTDI", 0x10C4: "CP210x"}


@dataclass
class Check:
    """One line of the report: what was checked, the verdict, and what was found (or what to do)."""

    name: str
    state: str
    detail: str


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("doctor", help="check the set-up: RMW, DDS profile, domain, discovery, serial ports, cameras, "
                                      "firmware (exit 1 when a check fails)")
    p.add_argument("--wait", type=float, default=2.0,
                   help="seconds to discover the graph and the driver's /diagnostics (0 = skip the graph)")
    p.add_argument("--clean-shm", action="store_true",
                   help="first remove the Fast DDS shared-memory files in /dev/shm that no living process holds "
                        "(left by processes that were killed), as `fastdds shm clean` does")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def check_shared_memory(clean: bool = False) -> list[Check]:
    """Fast DDS's shared-memory files: segments and ports in use, and those left behind by processes that ended
    without closing them (hexa_ros.shm), which hold RAM until removed (`clean`) or the next boot."""
    from hexa_ros import shm

    if clean:
        gone = shm.remove_stale()
        freed = (f"removed {gone.stale_owners} stale segments and ports ({gone.stale_bytes / 2**20:.0f} MB); "
                 if gone.stale_owners else "")
    else:
        freed = ""
    r = shm.scan()
    if not r.stale_owners:
        return [Check("dds shared memory", OK, f"{freed}{r.in_use} segments and ports in use in {shm.SHM_DIR}, "
                                               "none left behind")]
    return [Check("dds shared memory", WARN, f"{freed}{r.stale_owners} segments and ports in {shm.SHM_DIR} "
                                             f"({r.stale_bytes / 2**20:.0f} MB of RAM) belong to no living process "
                                             f"(killed ones); `hexa doctor --clean-shm` removes them")]


def check_environment() -> list[Check]:
    """RMW implementation, DDS profile, domain id and discovery range as a hexa process sees them."""
    from hexa_ros.env import PROFILE, RMW, defaults

    env = {**defaults(), **os.environ}
    out = []
    rmw = env["RMW_IMPLEMENTATION"]
    out.append(Check("rmw", OK if rmw == RMW else WARN,
                     rmw if rmw == RMW else f"{rmw} (hexa is tested with {RMW}; its DDS profile is for Fast DDS)"))
    profile = Path(env.get("FASTRTPS_DEFAULT_PROFILES_FILE", ""))
    if not profile.is_file():
        out.append(Check("dds profile", FAIL, f"FASTRTPS_DEFAULT_PROFILES_FILE={profile} does not exist "
                                              f"(hexa's: {PROFILE})"))
    else:
        out.append(_profile_check(profile, PROFILE))
    raw = env.get("ROS_DOMAIN_ID", "")
    try:
        domain = int(raw) if raw else 0
        state = OK if 0 <= domain <= 101 else WARN if domain <= 232 else FAIL
        note = {OK: "", WARN: " (above 101 a participant's ports may meet the OS's ephemeral ports; 0..101 are "
                               "safe on Linux)", FAIL: " (out of 0..232)"}[state]
        out.append(Check("domain", state, f"ROS_DOMAIN_ID={domain}" + ("" if raw else " (unset: 0)") + note))
    except ValueError:
        out.append(Check("domain", FAIL, f"ROS_DOMAIN_ID={raw!r} is not an integer"))
    rng = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "SUBNET"
    peers = env.get("ROS_STATIC_PEERS", "")
    known = rng.upper() in ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
    detail = f"ROS_AUTOMATIC_DISCOVERY_RANGE={rng}" + (f", ROS_STATIC_PEERS={peers}" if peers else "")
    if rng.upper() == "LOCALHOST":
        detail += " (this host only: a graph across PCs needs SUBNET)"
    if env.get("ROS_LOCALHOST_ONLY"):
        detail += f"; ROS_LOCALHOST_ONLY={env['ROS_LOCALHOST_ONLY']} is deprecated in Jazzy"
    out.append(Check("discovery", OK if known else FAIL, detail if known else detail + " (unknown value)"))
    return out


def _profile_check(path: Path, hexa_profile: Path) -> Check:
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        return Check("dds profile", FAIL, f"{path} is not readable XML: {exc}")
    text = {el.tag.split("}")[-1]: (el.text or "").strip() for el in root.iter()}
    seg = int(text["segment_size"]) if text.get("segment_size", "").isdigit() else None
    own = path.resolve() == hexa_profile.resolve()
    size = f"shared-memory segment {seg / 2**20:g} MB" if seg else "default shared-memory segment (512 KB)"
    state = OK if seg and seg >= 4 * 2**20 else WARN
    note = "" if state == OK else ": smaller than a 640x480 frame stream needs (hexa's profile has 32 MB)"
    return Check("dds profile", state, f"{path}{' (hexa)' if own else ''}, {size}{note}")


def check_serial_ports() -> list[Check]:
    """Serial ports present, the ones that look like the Arduinos, and whether this user may open them."""
    try:
        from serial.tools import list_ports
    except ImportError:
        return [Check("serial ports", FAIL, "pyserial is not installed (make setup)")]
    ports = sorted(list_ports.comports(), key=lambda p: p.device)
    usb = [p for p in ports if p.vid is not None]
    if not usb:
        return [Check("serial ports", WARN, "no USB serial port (robot mode needs the Uno and the Mega plugged in; "
                                            "simulation does not)")]
    by_id = {os.path.realpath(p): p for p in (str(x) for x in Path("/dev/serial/by-id").glob("*"))} \
        if Path("/dev/serial/by-id").is_dir() else {}
    out = []
    for p in usb:
        maker = SERIAL_VENDORS.get(p.vid, "")
        access = os.access(p.device, os.R_OK | os.W_OK)
        name = by_id.get(os.path.realpath(p.device), p.device)
        detail = f"{name} [{p.vid:04x}:{p.pid:04x}] {p.description}" + (f" ({maker})" if maker else "")
        if not access:
            detail += ": no read/write access (add the user to the 'dialout' group)"
        out.append(Check("serial port", OK if access else FAIL, detail))
    return out


def check_cameras() -> list[Check]:
    """RealSense cameras through pyrealsense2, when it is installed (`make setup-robot`)."""
    try:
        import pyrealsense2 as rs
    except ImportError:
        return [Check("cameras", WARN, "pyrealsense2 is not installed (`make setup-robot`; simulation does not "
                                       "need it)")]
    try:
        devices = list(rs.context().query_devices())
    except Exception as exc:  # noqa: BLE001 - librealsense raises its own error types
        return [Check("cameras", FAIL, f"pyrealsense2 cannot list devices: {exc}")]
    if not devices:
        return [Check("cameras", WARN, "pyrealsense2 finds no RealSense camera (robot mode needs two)")]
    info = rs.camera_info
    return [Check("camera", OK, f"{d.get_info(info.name)} serial {d.get_info(info.serial_number)} firmware "
                                f"{d.get_info(info.firmware_version)}") for d in devices]


def firmware_dir() -> Path | None:
    """hexa_driver/firmware of this checkout (where `make firmware` builds the .hex files)."""
    import importlib.util

    try:
        spec = importlib.util.find_spec("hexa_driver.driver_node")
    except ImportError:
        return None
    if spec is None or not spec.origin:
        return None
    d = Path(spec.origin).resolve().parents[1] / "firmware"     # hexa_driver/hexa_driver/driver_node.py
    return d if d.is_dir() else None


def check_firmware() -> list[Check]:
    """The .hex images `make firmware` builds, and the protocol/firmware versions their source declares."""
    from hexa.protocol import PROTOCOL_VERSION

    d = firmware_dir()
    if d is None:
        return [Check("firmware", FAIL, "hexa_driver/firmware not found (is hexa_driver installed?)")]
    header = (d / "common" / "hexa_link.h").read_text(encoding="utf-8", errors="replace")
    defs = dict(re.findall(r"#define\s+(HX_\w+_VERSION)\s+(\w+)", header))
    proto, fw = defs.get("HX_PROTOCOL_VERSION"), defs.get("HX_FIRMWARE_VERSION")
    out = []
    if proto is None or int(proto, 0) != PROTOCOL_VERSION:
        out.append(Check("firmware protocol", FAIL, f"the sketches speak protocol {proto}, the driver "
                                                    f"{PROTOCOL_VERSION}: rebuild and flash both boards"))
    version = f"firmware {fw}, protocol {proto}"
    for board, rel in (("uno", "build-uno/uno_servo.hex"), ("mega", "build-mega/mega_current.hex")):
        f = d / rel
        if f.is_file():
            out.append(Check(f"firmware {board}", OK, f"{f} ({version}); flash: make -C {d} flash-{board} "
                                                      f"PORT=/dev/ttyACM0"))
        else:
            out.append(Check(f"firmware {board}", WARN, f"{f} not built (`make firmware`; {version})"))
    return out


def check_graph(wait: float) -> list[Check]:
    """Nodes in the graph, and the firmware versions a running driver reports in /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray
    from hexa_ros.diagnostics import values_of

    from hexa_bringup.commands._ros import RosCli

    boards: dict[str, str] = {}
    with RosCli("hexa_doctor") as cli:
        import rclpy

        rmw = rclpy.utilities.get_rmw_implementation_identifier()

        def on_diag(msg: DiagnosticArray) -> None:
            for st in msg.status:
                values = values_of(st)
                if "firmware_version" in values:
                    boards[st.name] = f"{values['firmware_version']} ({st.message}, {values.get('port', '?')})"

        cli.node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 20)
        cli.spin_for(wait)
        nodes = cli.nodes()
    out = [Check("rmw loaded", OK, rmw),
           Check("graph", INFO, f"{len(nodes)} node(s) within {wait:g} s" + (f": {', '.join(nodes[:12])}"
                                                                             + (" …" if len(nodes) > 12 else "")
                                                                             if nodes else ""))]
    for name, text in sorted(boards.items()):
        out.append(Check("board", OK if text.startswith("0x") and not text.startswith("0x0 ") else WARN,
                         f"{name}: firmware {text}"))
    return out


def run(args: argparse.Namespace) -> int:
    checks = (check_environment() + check_shared_memory(args.clean_shm) + check_serial_ports() + check_cameras()
              + check_firmware())
    if args.wait > 0:
        try:
            checks += check_graph(args.wait)
        except Exception as exc:  # noqa: BLE001 - a middleware that does not load is a finding, not a crash
            checks.append(Check("rmw loaded", FAIL, f"rclpy cannot start: {' '.join(str(exc).split())}"))
    failed = [c for c in checks if c.state == FAIL]
    if args.json:
        print(json.dumps({"checks": [asdict(c) for c in checks], "failed": len(failed)}))
    else:
        width = max(len(c.name) for c in checks)
        for c in checks:
            print(f"{c.state.upper():<4}  {c.name:<{width}}  {c.detail}")
        print(f"{len(failed)} check(s) failed" if failed else "all checks passed", file=sys.stderr if failed
              else sys.stdout)
    return 1 if failed else 0

"""`hexa bringup sim|robot|replay`: start the whole graph, each node its own supervised process."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path


#: rad/s: the robot mode's approach from the measured pose to the trajectory's start (hobby servos: ≈ 6 rad/s)
ROBOT_APPROACH_SPEED = 0.3
#: the nodes of the 1 kHz safety path, which `--realtime-priority` raises (hexa_ros.realtime)
SAFETY_PATH = ("driver", "observer")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bringup", help="start and supervise the node graph (sim | robot | replay BAG | upsrpu)")
    p.add_argument("mode", choices=["sim", "robot", "replay", "upsrpu"],
                   help="sim: simulated Hexa + whole graph; robot: real hardware; replay: the processing nodes on a "
                        "bag's sensor inputs (never its recorded outputs); "
                        "upsrpu: simulated 3UPS+RPU with singularity monitor and SRM (namespace /upsrpu)")
    p.add_argument("bag", nargs="?", help="bag to replay (mode replay)")
    p.add_argument("--ns", default=None, help="namespace of the graph (default /hexa; /upsrpu for upsrpu)")
    p.add_argument("--params", default=None, help="ROS parameters YAML for all nodes (default: shipped config)")
    p.add_argument("--graph", help="YAML list of {name, cmd, required, respawn} to run instead of the built-in graph")
    p.add_argument("--uno", help="robot mode: serial port of the Arduino Uno (servos)")
    p.add_argument("--mega", help="robot mode: serial port of the Arduino Mega (currents)")
    p.add_argument("--cameras", nargs="*", default=[], help="robot mode: camera serial numbers (top side)")
    p.add_argument("--approach-speed", type=float, default=None, metavar="RAD_S",
                   help="the trajectory node first moves the arms from the camera's plate pose to the trajectory's "
                        "start at most this fast (rad/s); 0 = off (first command at full servo speed). "
                        f"Default {ROBOT_APPROACH_SPEED} in robot mode, 0 in sim (the simulator starts there)")
    p.add_argument("--realism", choices=["ideal", "realistic"], default=None,
                   help="sim mode: the simulated robot, ideal or realistic (docs/realism.md); default: the sim "
                        "node's parameter (realistic). On the realistic robot the other nodes run a calibration "
                        "overlay identified on it (cached per robot; ≈ 25 s the first time) unless "
                        "--description says otherwise")
    p.add_argument("--trajectory", default=None, metavar="FILE",
                   help="sim/robot: the trajectory node plays this pose file (CSV t x y z alpha beta gamma, SI; e.g. "
                        "from `hexa calibrate excite`) instead of its configured trajectory")
    p.add_argument("--collision-policy", choices=["hold", "retract", "ignore"], default=None,
                   help="sim/robot: the trajectory node's reaction to a collision START (default: its parameter, "
                        "hold); ignore for a calibration run on the uncalibrated model, whose false STARTs would "
                        "stop the excitation")
    p.add_argument("--description", default=None, metavar="YAML",
                   help="robot description or calibration overlay (`hexa calibrate identify`) for every node but "
                        "the simulator (which stays the robot); default: the packaged description")
    p.add_argument("--realtime-priority", type=int, default=None, metavar="N",
                   help="run the safety path (driver, observer) at SCHED_FIFO N (1-99; 50 on the robot PC, as "
                        "ros2_control) or 0 for normal scheduling; default: the parameters file's "
                        "`realtime_priority` (0). Needs root or an rtprio limit; without, the nodes run at normal "
                        "priority and say so (docs/running.md)")
    p.add_argument("--compose", action="store_true",
                   help="run pose + isolation in one process and observer + rnea + singularity in another "
                        "(hexa_ros.compose; fewer processes, one interpreter per group)")
    p.add_argument("--rate", type=float, default=1.0, help="replay: playback rate")
    p.add_argument("--topics", nargs="+", metavar="TOPIC",
                   help="replay: play these topics of the bag (relative names are in --ns) instead of the sensor "
                        "inputs (both cameras, motor_currents, joint_states)")
    p.add_argument("--exclude", nargs="+", default=[], metavar="TOPIC",
                   help="replay: do not play these topics (e.g. cam_side/color/image_raw)")
    p.add_argument("--log-dir", default=None, help="write each node's output to DIR/<node>.log")
    p.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0 = until Ctrl-C)")
    p.add_argument("--status-every", type=float, default=5.0, help="seconds between status tables")
    p.set_defaults(func=run)


def mode_node_args(args: argparse.Namespace) -> dict[str, list[str]]:
    """The `-p` overrides each node gets in `args.mode` (ports, cameras, the approach speed, the 3UPS+RPU inputs).

    Raises:
        hexa_bringup.supervisor.SupervisorError: robot mode without both ports, a negative approach speed.
    """
    from hexa_bringup.supervisor import SupervisorError

    node_args: dict[str, list[str]] = {}
    if args.mode == "robot":
        if not (args.uno and args.mega):
            raise SupervisorError("robot mode needs --uno PORT and --mega PORT (e.g. /dev/serial/by-id/...)")
        node_args["driver"] = ["-p", f"uno_port:={args.uno}", "-p", f"mega_port:={args.mega}"]
        serials = list(args.cameras) + [""] * (2 - len(args.cameras))
        for (name, cam), serial in zip((("camera_top", "cam_top"), ("camera_side", "cam_side")), serials):
            # quoted: unquoted digits would reach the node as an integer (and lose leading zeros)
            node_args[name] = ["-p", "source:=realsense", "-p", f"camera:={cam}", "-p", f"serial:='{serial}'"]
    if args.mode in ("robot", "sim"):
        speed = args.approach_speed if args.approach_speed is not None else (
            ROBOT_APPROACH_SPEED if args.mode == "robot" else None)
        if speed is not None:
            if not speed >= 0:
                raise SupervisorError(f"--approach-speed must be >= 0 rad/s, got {speed}")
            node_args["trajectory"] = ["-p", f"approach_speed:={float(speed)}"]
    if getattr(args, "realism", None):
        if args.mode != "sim":
            raise SupervisorError(f"--realism is for sim mode only, not {args.mode}")
        node_args["sim"] = ["-p", f"realism:={args.realism}"]
    if getattr(args, "trajectory", None):
        if args.mode not in ("sim", "robot"):
            raise SupervisorError(f"--trajectory is for sim and robot modes, not {args.mode}")
        path = Path(args.trajectory).resolve()
        if not path.is_file():
            raise SupervisorError(f"trajectory file {args.trajectory} does not exist")
        node_args["trajectory"] = node_args.get("trajectory", []) + ["-p", "trajectory:=file", "-p", f"file:={path}"]
    if getattr(args, "collision_policy", None):
        if args.mode not in ("sim", "robot"):
            raise SupervisorError(f"--collision-policy is for sim and robot modes, not {args.mode}")
        node_args["trajectory"] = node_args.get("trajectory", []) + ["-p", f"collision_policy:={args.collision_policy}"]
    if args.mode == "upsrpu":
        node_args["singularity"] = ["-p", "robot:=upsrpu", "-p", "input:=markers"]
        node_args["srm"] = ["-p", "input:=markers"]
    priority = getattr(args, "realtime_priority", None)
    if priority is not None:
        node_args = with_realtime_priority(node_args, priority)
    return node_args


def check_realtime_priority(priority: int) -> int:
    """`priority` as `--realtime-priority` takes it.

    Raises:
        hexa_bringup.supervisor.SupervisorError: `priority` outside 0..99 (hexa_ros.realtime.in_range).
    """
    from hexa_ros.realtime import in_range

    from hexa_bringup.supervisor import SupervisorError

    if not in_range(priority):
        raise SupervisorError(f"--realtime-priority must be 0 (normal scheduling) or a SCHED_FIFO priority 1-99, "
                              f"got {priority}")
    return int(priority)


def with_realtime_priority(node_args: dict[str, list[str]], priority: int) -> dict[str, list[str]]:
    """`node_args` with `realtime_priority:=priority` for the safety path's nodes (`SAFETY_PATH`).

    Raises:
        hexa_bringup.supervisor.SupervisorError: `priority` outside 0..99.
    """
    from hexa_ros.realtime import REALTIME_PRIORITY

    priority = check_realtime_priority(priority)
    out = dict(node_args)
    for name in SAFETY_PATH:
        out[name] = out.get(name, []) + ["-p", f"{REALTIME_PRIORITY}:={priority}"]
    return out


def _say(line: str) -> None:
    print(f"hexa bringup: {line}", flush=True)


def description_args(description: str, specs: list, node_args: dict[str, list[str]],
                     log: Callable[[str], None] = _say) -> dict[str, list[str]]:
    """`node_args` with `description:=PATH` for every node of `specs` but the simulator (the robot itself).

    Raises:
        hexa_bringup.supervisor.SupervisorError: the file is missing or not a valid description / overlay.
    """
    from hexa.robots.hexa_description import calibration_summary, load_hexa
    from hexa.robots.schema import RobotDescriptionError
    from hexa_bringup.supervisor import SupervisorError

    from hexa_bringup.graphs import with_description

    try:
        log(calibration_summary(load_hexa(Path(description).resolve())))
    except RobotDescriptionError as exc:
        raise SupervisorError(str(exc)) from exc
    return with_description(description, specs, node_args)


def sim_robot(params: Path, node_args: dict[str, list[str]], namespace: str = "/hexa") -> tuple[str, int]:
    """(realism, seed) of the simulator that sim mode starts: its `-p` overrides, else what the parameters file gives
    the node `<namespace>/sim` (every section that matches it, wildcards included, as rcl applies them), else the
    node's defaults.

    Raises:
        hexa_bringup.supervisor.SupervisorError: the parameters file is not readable YAML.
    """
    import yaml

    from hexa_bringup.commands.service import node_parameters
    from hexa_bringup.graphs import DEFAULT_REALISM
    from hexa_bringup.supervisor import SupervisorError

    values: dict[str, object] = {"realism": DEFAULT_REALISM, "seed": 0}
    if params.is_file():
        try:
            data = yaml.safe_load(params.read_text(encoding="utf-8")) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise SupervisorError(f"cannot read parameters file {params}: {exc}") from exc
        if isinstance(data, dict):
            given = node_parameters(data, f"{namespace.rstrip('/')}/sim")
            values.update({k: v for k, v in given.items() if k in values})
    args = node_args.get("sim", [])
    for a in args:
        name, _, value = a.partition(":=")
        if name in values and value:
            values[name] = value
    try:
        return str(values["realism"]), int(str(values["seed"]))
    except ValueError as exc:
        raise SupervisorError(f"the simulator's seed must be an integer, got {values['seed']!r}") from exc


def with_nodes_description(mode: str, ns: str, params: Path, node_args: dict[str, list[str]],
                           description: str | Path | None = None,
                           log: Callable[[str], None] = _say) -> dict[str, list[str]]:
    """`node_args` with the description every node but the simulator runs: `description` if given, else in sim mode
    the calibration overlay of the simulated robot (`calibrated_description`), else unchanged. `log` gets the
    calibration's progress and the description's summary.

    Raises:
        hexa_bringup.supervisor.SupervisorError: the robot cannot be calibrated, or the description is invalid.
    """
    from hexa_bringup.graphs import build_graph

    if mode == "sim" and not description:
        description = calibrated_description(params, node_args, ns, log)
    if not description:
        return node_args
    return description_args(str(description), build_graph(mode, ns, params, node_args), node_args, log)


def calibrated_description(params: Path, node_args: dict[str, list[str]], namespace: str = "/hexa",
                           log: Callable[[str], None] = _say) -> Path | None:
    """The calibration overlay the nodes of sim mode run when the simulator is the realistic robot (identified on
    that robot, cached: hexa_bringup.demo_run.nodes_description), None on the ideal robot.

    Raises:
        hexa_bringup.supervisor.SupervisorError: the robot cannot be calibrated.
    """
    from hexa_bringup.demo_run import nodes_description
    from hexa_bringup.supervisor import SupervisorError

    realism, seed = sim_robot(params, node_args, namespace)
    try:
        return nodes_description(realism, seed, log=log)
    except ValueError as exc:   # an unknown realism, CalibrationError, RecordingError
        raise SupervisorError(f"cannot calibrate the simulated {realism} robot of seed {seed}: {exc}") from exc


def _bag_topics(bag: str) -> list[str]:
    """The topics of `bag`.

    Raises:
        hexa_bringup.supervisor.SupervisorError: the bag is missing or unreadable.
    """
    from hexa_bringup.bag import bag_topics
    from hexa_bringup.supervisor import SupervisorError

    if not Path(bag).exists():
        raise SupervisorError(f"bag {bag} does not exist")
    try:
        return list(bag_topics(bag))
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types; all mean "not a readable bag"
        raise SupervisorError(f"cannot read bag {bag}: {exc}") from exc


def run(args: argparse.Namespace) -> int:
    from hexa_bringup.graphs import DEFAULT_PARAMS, build_graph, load_graph_file, replay_topics
    from hexa_bringup.rosenv import ros_env
    from hexa_bringup.supervisor import NodeSpec, Supervisor, SupervisorError

    try:
        if args.graph:
            specs = load_graph_file(args.graph)
        else:
            node_args = mode_node_args(args)
            params = Path(args.params) if args.params else DEFAULT_PARAMS
            ns = args.ns or ("/upsrpu" if args.mode == "upsrpu" else "/hexa")
            node_args = with_nodes_description(args.mode, ns, params, node_args, getattr(args, "description", None))
            specs = build_graph(args.mode, ns, params, node_args, compose=args.compose)
            if args.mode == "replay":
                if not args.bag:
                    raise SupervisorError("replay mode needs a BAG argument")
                topics = replay_topics(_bag_topics(args.bag), ns, args.topics, args.exclude)
                print(f"hexa bringup: replaying {len(topics)} topics of {args.bag} and /clock: {', '.join(topics)}",
                      flush=True)
                specs.insert(0, NodeSpec("play", [sys.executable, "-m", "hexa_bringup.cli", "play", args.bag,
                                                  "--clock", "--rate", str(args.rate), "--wait", "3",
                                                  "--topics", *topics],
                                         required=True, respawn=False, ends_graph=True))
        sup = Supervisor(specs, ros_env(None, localhost_only=False), log_dir=args.log_dir,
                         status_every=args.status_every)
    except SupervisorError as exc:
        print(f"hexa bringup: {exc}", file=sys.stderr)
        return 2
    return sup.run(duration=args.duration)



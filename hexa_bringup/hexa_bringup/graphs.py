"""The node graphs `hexa bringup` starts: which node modules run, with which arguments, per mode."""
from __future__ import annotations

import importlib.util
import sys
from collections.abc import Iterable
from pathlib import Path

import yaml

from hexa_bringup.supervisor import NodeSpec, SupervisorError

CONFIG_DIR = Path(__file__).resolve().parent / "config"
DEFAULT_PARAMS = CONFIG_DIR / "hexa_params.yaml"
#: the simulated robot of `hexa-sim`, `hexa demo` and `hexa bringup sim` unless told otherwise ("ideal" | "realistic",
#: hexa.sim.realism); on the realistic robot the other nodes run a calibration overlay identified on it
#: (hexa_bringup.demo_run.nodes_description; docs/realism.md, "The live graph on the realistic robot")
DEFAULT_REALISM = "realistic"
#: simulator real-time factor `hexa demo` asks for. The pacing drops the wall time of host stalls (hexa.sim.pacing),
#: so the factor reached is lower and follows the host's load (docs/demo.md, "Real time"); the free motion's residual
#: noise grows with the rate, and at 0.55 on a slow host it comes within reach of a false START
DEMO_REAL_TIME_FACTOR = 0.5

# name, module, required, modes
NODES: list[tuple[str, str, bool, tuple[str, ...]]] = [
    ("sim", "hexa_bringup.sim_node", True, ("sim",)),
    ("driver", "hexa_driver.driver_node", True, ("sim", "robot")),
    ("camera_top", "hexa_vision.camera_node", True, ("robot",)),
    ("camera_side", "hexa_vision.camera_node", True, ("robot",)),
    ("pose", "hexa_vision.pose_node", True, ("sim", "robot", "replay")),
    ("observer", "hexa_dynamics.observer_node", True, ("sim", "robot", "replay")),
    ("isolation", "hexa_vision.isolation_node", True, ("sim", "robot", "replay")),
    ("rnea", "hexa_dynamics.rnea_node", True, ("sim", "robot", "replay")),
    ("singularity", "hexa_dynamics.singularity_node", False, ("sim", "robot", "replay")),
    ("trajectory", "hexa_dynamics.trajectory_node", False, ("sim", "robot")),
    # the 3UPS+RPU (seed 003), namespace /upsrpu: simulated robot + tracking, indices, singularity release
    ("upsrpu_sim", "hexa_dynamics.upsrpu_sim_node", True, ("upsrpu",)),
    ("singularity", "hexa_dynamics.singularity_node", True, ("upsrpu",)),
    ("srm", "hexa_dynamics.srm_node", True, ("upsrpu",)),
]
MODES = ("sim", "robot", "replay", "upsrpu")
#: the sensor inputs of the processing graph, relative to its namespace: what the hardware (or the simulator) publishes
#: and the nodes of "replay" mode read: both cameras' colour, aligned depth and camera_info (realsense-ros layout)
#: and the driver's two streams. `hexa bringup replay` plays these from a bag, never the recorded outputs; `hexa bench
#: graph` plays the same set.
CAMERAS = ("cam_top", "cam_side")
CAMERA_TOPICS = ("color/image_raw", "aligned_depth_to_color/image_raw", "color/camera_info")
SENSOR_INPUTS = tuple(f"{c}/{t}" for c in CAMERAS for t in CAMERA_TOPICS) + ("motor_currents", "joint_states")
#: the node class of each module (for composition: hexa_ros.compose builds it)
NODE_CLASSES = {"hexa_vision.pose_node": "PoseNode", "hexa_vision.isolation_node": "IsolationNode",
                "hexa_dynamics.observer_node": "ObserverNode", "hexa_dynamics.rnea_node": "RneaNode",
                "hexa_dynamics.singularity_node": "SingularityNode"}
#: `--compose`: the processes that hold several nodes each. Vision (pose + isolation) and dynamics (observer + rnea +
#: singularity) stay apart: the observer's per-sample latency must not wait for a camera frame's marker fit.
COMPOSED = {"vision": ("pose", "isolation"), "dynamics": ("observer", "rnea", "singularity")}


def module_available(module: str) -> bool:
    """True when `module` can be imported (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def ros_args(name: str, namespace: str, params: Path | None, sim_time: bool, extra: list[str] | None = None
             ) -> list[str]:
    """The `--ros-args` part of a node's command line: remaps, the parameters file, then `-p` overrides (in ROS 2
    the later of a file value and a `-p` value wins)."""
    args = ["--ros-args", "-r", f"__ns:={namespace}", "-r", f"__node:={name}"]
    if params is not None and params.is_file():  # first: later -p arguments override the file
        args += ["--params-file", str(params)]
    return args + ["-p", f"use_sim_time:={'true' if sim_time else 'false'}"] + (extra or [])


def build_graph(mode: str, namespace: str = "/hexa", params: Path | None = DEFAULT_PARAMS,
                node_args: dict[str, list[str]] | None = None, compose: bool = False) -> list[NodeSpec]:
    """NodeSpecs for `mode` in MODES ("sim", "robot", "replay" for the Hexa; "upsrpu" for the 3UPS+RPU).

    compose: the nodes of each COMPOSED group that take no extra arguments run in one process
    (hexa_ros.compose), named after the group; the others keep a process each.

    Raises:
        SupervisorError: a required node's module is not installed (names it and the package to build).
    """
    if mode not in MODES:
        raise SupervisorError(f"unknown bringup mode {mode!r}; use one of {', '.join(MODES)}")
    specs = []
    missing = []
    for name, module, required, modes in NODES:
        if mode not in modes:
            continue
        if not module_available(module):
            if required:
                missing.append(f"{name} ({module})")
            continue
        extra = (node_args or {}).get(name, [])
        sim_time = mode in ("sim", "replay")
        # through hexa_ros.start: a Ctrl-C while the module still imports stops it cleanly too
        cmd = [sys.executable, "-m", "hexa_ros.start", module] + ros_args(name, namespace, params, sim_time, extra)
        specs.append(NodeSpec(name, cmd, required=required))
    if missing:
        raise SupervisorError(f"cannot bring up '{mode}': required node module(s) not installed: "
                              f"{', '.join(missing)}. Run `make setup`; if the module does not exist in this "
                              f"checkout, that node is not written yet (see README, Status).")
    return _composed(specs, mode, namespace, params, node_args or {}) if compose else specs


def _composed(specs: list[NodeSpec], mode: str, namespace: str, params: Path | None,
              node_args: dict[str, list[str]]) -> list[NodeSpec]:
    """`specs` with each COMPOSED group's nodes (those without extra arguments) in one hexa_ros.compose process."""
    modules = {name: module for name, module, _r, modes in NODES if mode in modes}
    present = {s.name: s for s in specs}
    out, grouped = [], set()
    for group, members in COMPOSED.items():
        names = [n for n in members if n in present and not node_args.get(n) and modules[n] in NODE_CLASSES]
        if len(names) < 2:
            continue
        parts = [f"{n}={modules[n]}:{NODE_CLASSES[modules[n]]}" for n in names]
        args = ros_args(group, namespace, params, mode in ("sim", "replay"))
        del args[3:5]              # no global "-r __node:=": each composed node is renamed on its own
        cmd = [sys.executable, "-m", "hexa_ros.compose", *parts] + args
        out.append(NodeSpec(group, cmd, required=any(present[n].required for n in names)))
        grouped.update(names)
    return [s for s in specs if s.name not in grouped] + out


def _absolute(topic: str, namespace: str) -> str:
    return topic if topic.startswith("/") else f"{namespace.rstrip('/')}/{topic}"


def replay_topics(bag: Iterable[str], namespace: str = "/hexa", topics: Iterable[str] | None = None,
                  exclude: Iterable[str] = ()) -> list[str]:
    """The topics of a bag that `hexa bringup replay` plays: by default the SENSOR_INPUTS in `namespace` that the bag
    holds (never the recorded outputs, which the live nodes publish again); `topics` replaces that choice, `exclude`
    removes topics from it. Relative names are resolved in `namespace`.

    Raises:
        SupervisorError: a topic of `topics` is not in the bag, or nothing is left to play (naming what the bag holds).
    """
    held = set(bag)
    if topics:
        chosen = [_absolute(t, namespace) for t in topics]
        absent = [t for t in chosen if t not in held]
        if absent:
            raise SupervisorError(f"the bag has no topic {', '.join(absent)}; it holds {', '.join(sorted(held))}")
    else:
        chosen = [t for t in (_absolute(t, namespace) for t in SENSOR_INPUTS) if t in held]
    dropped = {_absolute(t, namespace) for t in exclude}
    chosen = [t for t in dict.fromkeys(chosen) if t not in dropped]
    if not chosen:
        raise SupervisorError(f"nothing to replay: the bag holds none of the sensor inputs "
                              f"{', '.join(_absolute(t, namespace) for t in SENSOR_INPUTS)} (or all were excluded); "
                              f"it holds {', '.join(sorted(held)) or 'no topic'}. Name topics with --topics, or "
                              f"--ns if the bag was recorded in another namespace")
    return chosen


def load_graph_file(path: str | Path) -> list[NodeSpec]:
    """NodeSpecs from a YAML file: a list of {name, cmd: [..], required, respawn, ends_graph}.

    Raises:
        SupervisorError: the file is missing or malformed (naming the entry).
    """
    p = Path(path)
    if not p.is_file():
        raise SupervisorError(f"graph file {p} does not exist")
    data = yaml.safe_load(p.read_text())
    if not isinstance(data, list):
        raise SupervisorError(f"graph file {p} must be a list of nodes")
    specs = []
    for i, item in enumerate(data):
        if not isinstance(item, dict) or "name" not in item or "cmd" not in item:
            raise SupervisorError(f"graph file {p}: entry {i} needs 'name' and 'cmd'")
        cmd = item["cmd"]
        if isinstance(cmd, str) or not all(isinstance(c, str) for c in cmd):
            raise SupervisorError(f"graph file {p}: entry {item['name']!r}: 'cmd' must be a list of strings")
        specs.append(NodeSpec(str(item["name"]), list(cmd), bool(item.get("required", True)),
                              bool(item.get("respawn", True)), bool(item.get("ends_graph", False))))
    return specs


def with_description(description: str | Path, specs: Iterable[NodeSpec],
                     node_args: dict[str, list[str]]) -> dict[str, list[str]]:
    """`node_args` with `description:=PATH` (absolute) for every node of `specs` but the simulator (the robot itself)
    and the bag player."""
    path = Path(description).resolve()
    out = {k: list(v) for k, v in node_args.items()}
    for spec in specs:
        if spec.name not in ("sim", "play"):
            out[spec.name] = out.get(spec.name, []) + ["-p", f"description:={path}"]
    return out

"""Every `hexa …` command line of README.md runs: the README cannot rot.

The commands are read from the README itself: each line starting with `hexa ` in a bash/sh/console code block, each
inline code span `hexa …`, and each line of the plain code blocks (the CLI synopsis). They run in README order, in
one scratch directory, against one `hexa bringup sim` graph (started once for the module, in its own
ROS_DOMAIN_ID), so an example that records a bag can be followed by one that reads it.

How a command is run depends on its form:
- **run**: a complete command line runs to its end and must exit 0 (within RUN_TIMEOUT s);
- **stream**: a command that runs until Ctrl-C (an echo without --once, hz without --duration, a recording without
  --duration, a bringup, `hexa view`) must still be running after STREAM_SECONDS s (a recording: after it says it
  records) and then stop cleanly on SIGINT; a bringup runs in a domain of its own (it starts its own graph);
- **synopsis**: a line with placeholders (`BAG`, `N`, `...`, `a|b`, `[opt]`) names its subcommand: `hexa <verbs> --help`
  must exit 0 for each alternative;
- **parse**: the commands in CHEAP (minutes of work, or hardware) are parsed by the CLI's own parser — every option
  and value must be valid — without running them; each entry says why.
No command may print a Python traceback.
"""
from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
HEXA = [sys.executable, "-m", "hexa_bringup.cli"]
RUN_TIMEOUT = 240.0
STREAM_SECONDS = 3.0

#: commands parsed, not run: (leading words) → why. Keep this list short.
CHEAP: dict[tuple[str, ...], str] = {
    ("demo",): "three whole-graph cases take minutes (`make demo`; test_graph_demo.py runs the graph per case)",
    ("bench",): "benchmarks take minutes (`make bench`)",
    ("srm", "--all"): "five trajectories x two variants take minutes (test_srm_*.py cover the algorithm)",
    ("eval",): "a randomized campaign takes minutes to hours",
    ("calibrate",): "the excitation design and the identification take minutes (test_calibration*.py cover them)",
    ("bringup", "robot"): "needs the robot's serial ports and RealSense cameras",
    ("bringup", "sim"): "a second simulated graph beside the module's own `hexa bringup sim`",
}
#: stream commands that first say on stderr that they are working (then STREAM_SECONDS more): a recorder subscribes
#: only once it has discovered the topics
READY = {("record",): "hexa record: recording "}
#: a placeholder token: BAG, N, TOPSERIAL, R, …, ..., a|b, [x], {a|b}, 1..5
PLACEHOLDER = re.compile(r"^(?:[A-Z][A-Z0-9_]*|.*(?:\.\.\.|…|\||\[|\]).*|\d+\.\.\d+)$")


# ---------------------------------------------------------------------------------------------------------------
# reading the README


def readme_commands(text: str) -> list[tuple[str, str]]:
    """(kind, command) in README order; kind "line" (a code block of a shell), "inline" (a code span) or "synopsis"
    (a plain code block: the CLI's synopsis, text after two spaces is a description)."""
    out: list[tuple[int, str, str]] = []
    fence = re.compile(r"^```(\w*)\s*$", re.M)
    pos, blocks = 0, []
    matches = list(fence.finditer(text))
    for opening, closing in zip(matches[::2], matches[1::2]):
        blocks.append((opening.start(), closing.end(), opening.group(1), text[opening.end():closing.start()]))
    prose = []
    for start, end, lang, body in blocks:
        prose.append((pos, text[pos:start]))
        pos = end
        for line in body.splitlines():
            line = line.strip()
            if line.startswith("$ "):
                line = line[2:]
            if not line.startswith("hexa "):
                continue
            if lang in ("bash", "sh", "shell", "console"):
                out.append((start, "line", line.split("  #", 1)[0].strip()))
            else:
                out.append((start, "synopsis", re.split(r"\s{2,}", line, maxsplit=1)[0]))
    prose.append((pos, text[pos:]))
    for offset, chunk in prose:
        for m in re.finditer(r"(?<!`)`([^`]+)`(?!`)", chunk):
            span = " ".join(m.group(1).split())
            if span.startswith("hexa "):
                out.append((offset + m.start(), "inline", span))
    out.sort(key=lambda r: r[0])
    seen, commands = set(), []
    for _pos, kind, cmd in out:
        if (kind, cmd) not in seen:
            seen.add((kind, cmd))
            commands.append((kind, cmd))
    return commands


def words(cmd: str) -> list[str]:
    try:
        return shlex.split(cmd)[1:]
    except ValueError:                           # an unbalanced quote in a synopsis line
        return cmd.split()[1:]


def has_placeholder(cmd: str) -> bool:
    """A placeholder among the unquoted words of `cmd` (a quoted YAML value such as '[3, 3]' is not one)."""
    try:
        raw = shlex.split(cmd, posix=False)[1:]
    except ValueError:
        raw = cmd.split()[1:]
    return any(PLACEHOLDER.match(w) for w in raw if not w.startswith(("'", '"')))


def parses(argv: list[str]) -> bool:
    """True when the CLI's own parser accepts `argv` (every option and value valid)."""
    import contextlib
    import io

    from hexa_bringup.cli import build_parser

    try:
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(argv)
    except SystemExit:
        return False
    return True


def subcommand_paths(argv: list[str]) -> list[list[str]]:
    """The subcommand words `argv` starts with, one list per alternative ("topic list|echo" → two)."""
    from hexa_bringup.cli import build_parser

    paths: list[list[str]] = [[]]
    parser = build_parser()
    parsers = [parser]
    for w in argv:
        choices = _subparser_choices(parsers[0])
        alts = [a for a in re.split(r"[|/]", w.strip("{}[]")) if a]
        if not choices or not alts or not all(a in choices for a in alts):
            break
        paths = [p + [a] for p in paths for a in alts]
        parsers = [choices[alts[0]]]
    return paths


def _subparser_choices(parser) -> dict:
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices
    return {}


def classify(kind: str, cmd: str) -> tuple[str, str]:
    """(how, why): "run" | "stream" | "synopsis" | "parse"."""
    argv = words(cmd)
    if kind == "synopsis" or has_placeholder(cmd) or (argv and re.search(r"[/|]", argv[0])):
        return "synopsis", "placeholders"
    paths = subcommand_paths(argv)
    if paths and len(paths[0]) == len(argv) and not parses(argv):
        return "synopsis", "names a subcommand (`hexa topic`), not a command line"
    for prefix, why in CHEAP.items():
        if tuple(argv[:len(prefix)]) == prefix:
            return "parse", why
    verb = argv[:2]
    bounded = {"--once", "-n", "--count", "--timeout", "--duration", "--layout", "--help", "-h"}
    if argv[:1] in (["bringup"], ["view"]) and not bounded & set(argv):
        return "stream", "runs until Ctrl-C"
    if verb in (["topic", "echo"], ["topic", "hz"]) and not bounded & set(argv):
        return "stream", "runs until Ctrl-C"
    if argv[:1] == ["record"] and "--duration" not in argv:
        return "stream", "records until Ctrl-C"
    if verb == ["topic", "pub"] and not {"--once", "-1", "-t", "--times"} & set(argv):
        return "stream", "publishes until Ctrl-C"
    return "run", ""


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))


# ---------------------------------------------------------------------------------------------------------------
# the graph and the runner


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("readme")


@pytest.fixture(scope="module")
def sim_graph(module_ros_domain_id, workdir):
    """`hexa bringup sim` for the whole module; its environment once the observer publishes residuals."""
    from hexa_bringup.rosenv import ros_env

    env = dict(ros_env(module_ros_domain_id), MUJOCO_GL="egl")
    graph = subprocess.Popen([*HEXA, "bringup", "sim", "--log-dir", str(workdir / "graph_logs"), "--status-every",
                              "1e9"], env=env, cwd=str(workdir), start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        ready = subprocess.run([*HEXA, "topic", "echo", "/hexa/residual", "--once", "--timeout", "180"], env=env,
                               cwd=str(workdir), capture_output=True, text=True, timeout=240)
        assert ready.returncode == 0, f"the simulated graph did not come up: {ready.stderr[-2000:]}"
        yield env
    finally:
        _stop(graph)


def _stop(proc: subprocess.Popen, grace: float = 20.0) -> tuple[str, str]:
    out = err = ""
    for sig, wait in ((signal.SIGINT, grace), (signal.SIGKILL, 10.0)):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            out, err = proc.communicate(timeout=wait)
            break
        except subprocess.TimeoutExpired:
            continue
    if proc.poll() is None:
        proc.wait(timeout=10)
    return out or "", err or ""


def _interrupt(proc: subprocess.Popen, grace: float = 20.0) -> None:
    """SIGINT (Ctrl-C) to the process group; SIGKILL after `grace` s."""
    for sig, wait in ((signal.SIGINT, grace), (signal.SIGKILL, 10.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


def _no_traceback(cmd: str, out: str, err: str) -> None:
    assert "Traceback (most recent call last)" not in out + err, f"`{cmd}` printed a traceback:\n{err[-3000:]}"


@pytest.mark.parametrize("kind,cmd", COMMANDS, ids=[c for _k, c in COMMANDS])
def test_readme_command(kind, cmd, sim_graph, workdir, ros_domain_id):
    argv = words(cmd)
    how, why = classify(kind, cmd)
    env = sim_graph
    if how == "synopsis":
        paths = subcommand_paths(argv)
        assert paths and paths[0], f"`{cmd}` names no hexa subcommand"
        for path in paths:
            r = subprocess.run([*HEXA, *path, "--help"], env=env, cwd=str(workdir), capture_output=True, text=True,
                               timeout=120)
            assert r.returncode == 0, f"`hexa {' '.join(path)} --help` failed: {r.stderr[-2000:]}"
        return
    if how == "parse":
        from hexa_bringup.cli import build_parser

        try:
            build_parser().parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"`{cmd}` does not parse (exit {exc.code}); not run because: {why}")
        return
    if argv[:1] == ["view"] and "--port" not in argv:
        argv += ["--port", "0"]              # any free port: a concurrent `hexa view` may hold 8765
    if argv[:1] == ["bringup"]:              # its own graph, in its own domain
        from hexa_bringup.rosenv import ros_env

        env = dict(ros_env(ros_domain_id), MUJOCO_GL="egl")
    proc = subprocess.Popen([*HEXA, *argv], env=env, cwd=str(workdir), start_new_session=True, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    if how == "run":
        try:
            out, err = proc.communicate(timeout=RUN_TIMEOUT)
        except subprocess.TimeoutExpired:
            out, err = _stop(proc)
            pytest.fail(f"`{cmd}` did not finish within {RUN_TIMEOUT:g} s:\n{err[-2000:]}")
        _no_traceback(cmd, out, err)
        assert proc.returncode == 0, f"`{cmd}` exited {proc.returncode}:\n{err[-2000:]}"
        return
    marker = next((m for prefix, m in READY.items() if tuple(argv[:len(prefix)]) == prefix), None)
    err_lines: list[str] = []
    out_lines: list[str] = []
    readers = [threading.Thread(target=lambda f=f, acc=acc: acc.extend(iter(f.readline, "")), daemon=True)
               for f, acc in ((proc.stderr, err_lines), (proc.stdout, out_lines))]
    for r in readers:
        r.start()
    deadline = time.monotonic() + 90.0
    while marker and proc.poll() is None and time.monotonic() < deadline \
            and not any(marker in line for line in list(err_lines)):
        time.sleep(0.2)
    try:
        proc.wait(timeout=STREAM_SECONDS)
        ended = True
    except subprocess.TimeoutExpired:
        ended = False
        _interrupt(proc)
    for r in readers:
        r.join(timeout=10)
    out, err = "".join(out_lines), "".join(err_lines)
    _no_traceback(cmd, out, err)
    if ended:      # a stream command that ends by itself (a replay at the bag's end) must have succeeded
        assert proc.returncode == 0, f"`{cmd}` exited {proc.returncode} within {STREAM_SECONDS:g} s:\n{err[-2000:]}"
    else:
        assert proc.returncode in (0, 130, -signal.SIGINT), \
            f"`{cmd}` ({why}) did not stop cleanly on Ctrl-C (exit {proc.returncode}):\n{err[-2000:]}"


def test_the_readme_has_commands_of_every_kind():
    """The parser finds the README's command lines (a README reshaped so that none is found would pass silently)."""
    kinds = {classify(k, c)[0] for k, c in COMMANDS}
    assert {"run", "stream", "synopsis", "parse"} <= kinds, kinds
    assert len(COMMANDS) >= 30


# ---------------------------------------------------------------------------------------------------------------
# the topic table

#: ROS's own topics of every node, described in the text under the table
ROS_OWN = {"/rosout", "/parameter_events"}

GRAPH_DUMP = """
import json, time
from hexa_bringup.commands._ros import RosCli, qos_dict
with RosCli("hexa_readme_table") as cli:
    seen, still = None, time.monotonic()
    while time.monotonic() - still < 3.0:
        now = sorted(cli.node.get_topic_names_and_types())
        if now != seen:
            seen, still = now, time.monotonic()
        cli.spin_for(0.2)
    out = {}
    for name, types in seen:
        pubs = [(i.node_name, qos_dict(i.qos_profile)) for i in cli.node.get_publishers_info_by_topic(name)]
        pubs = [(n, q["reliability"], q["durability"]) for n, q in pubs if not n.startswith("hexa_")]
        if pubs:
            out[name] = {"types": types, "publishers": pubs}
print(json.dumps(out))
"""


def _braces(raw: str) -> list[str]:
    """Every name a README pattern stands for, expanding each `{a,b}` group as a shell does."""
    m = re.match(r"^(.*?)\{([^}]+)\}(.*)$", raw)
    return [name for alt in m.group(2).split(",") for name in _braces(m.group(1) + alt + m.group(3))] if m else [raw]


def topic_table(text: str, ns: str = "/hexa") -> dict[str, tuple[str, str, str]]:
    """topic → (type "pkg/Name", reliability, durability) from the README's table with a QoS column."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| topic | type | from | QoS |"))
    out = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        names = []
        for raw in re.findall(r"`([^`]+)`", cells[0]):
            for name in _braces(raw):
                names.append(name if name.startswith("/") else f"{ns}/{name}")
        types = [t.strip() for t in cells[1].split(",")]
        qos = cells[3]
        reliability = "best_effort" if qos.startswith("best effort") else "reliable"
        durability = "transient_local" if "transient local" in qos else "volatile"
        for k, name in enumerate(names):
            kind = types[k * len(types) // len(names)] if len(types) > 1 else types[0]
            out[name] = (kind, reliability, durability)
    return out


def test_the_topic_table_lists_every_published_topic_with_its_type_and_qos(sim_graph, workdir):
    import json

    table = topic_table(README.read_text(encoding="utf-8"))
    r = subprocess.run([sys.executable, "-c", GRAPH_DUMP], env=sim_graph, cwd=str(workdir), capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    graph = {t: v for t, v in json.loads(r.stdout).items() if t not in ROS_OWN}
    missing = sorted(set(graph) - set(table))
    assert not missing, f"published by `hexa bringup sim` but not in the README's topic table: {missing}"
    stale = sorted(set(table) - set(graph))
    assert not stale, f"in the README's topic table but not published by `hexa bringup sim`: {stale}"
    for topic, v in sorted(graph.items()):
        kind, reliability, durability = table[topic]
        assert [t.replace("/msg/", "/") for t in v["types"]] == [kind], (topic, v["types"], kind)
        for node, rel, dur in v["publishers"]:
            assert (rel, dur) == (reliability, durability), (topic, node, rel, dur, "README:", reliability,
                                                             durability)

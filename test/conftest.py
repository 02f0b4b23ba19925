"""Shared pytest fixtures: a unique ROS_DOMAIN_ID per test and child-process cleanup."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Iterator

import pytest

# Headless MuJoCo rendering (EGL) for every test, also when pytest is run without the Makefile.
os.environ.setdefault("MUJOCO_GL", "egl")
try:
    # The test process is a ROS peer too: its participants take hexa's Fast DDS profile. Fast DDS reads the profile
    # file once per process, at the first participant: a test calling rclpy.init() before setting it would leave
    # every later test of the process with the 512 KB shared-memory segment, whose image messages go over UDP and
    # are lost under load.
    from hexa_ros.env import apply_defaults
except ImportError:         # before `make setup`: the ROS tests skip themselves
    pass
else:
    apply_defaults()

REPO = Path(__file__).resolve().parents[1]


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """After the run (in the main process, not in an xdist worker): remove the Fast DDS shared-memory files that the
    child processes killed at teardown left in /dev/shm; each holds RAM until the next boot."""
    if hasattr(session.config, "workerinput"):
        return
    try:
        from hexa_ros.shm import remove_stale
    except ImportError:
        return
    remove_stale()

TEST_DIR = Path(__file__).resolve().parent
if str(TEST_DIR) not in sys.path:
    sys.path.insert(0, str(TEST_DIR))


@pytest.fixture
def ros_domain_id() -> Iterator[int]:
    """A ROS_DOMAIN_ID (1..100) no other test on this machine holds right now (flock on /tmp), freed afterwards."""
    from rosdomain import NoFreeDomain, held_ros_domain

    try:
        with held_ros_domain() as domain:
            yield domain
    except NoFreeDomain as exc:
        pytest.fail(str(exc))


@pytest.fixture(scope="module")
def module_ros_domain_id() -> Iterator[int]:
    """Like ros_domain_id, held for a whole module (module-scoped graph runs); searched from 100 down."""
    from rosdomain import NoFreeDomain, held_ros_domain

    try:
        with held_ros_domain(range(100, 0, -1)) as domain:
            yield domain
    except NoFreeDomain as exc:
        pytest.fail(str(exc))


@pytest.fixture
def ros_env(ros_domain_id: int) -> dict[str, str]:
    """Environment for child ROS processes: rmw_fastrtps, hexa's DDS profile, unique domain, localhost only."""
    from hexa_bringup.rosenv import ros_env as make_env

    return make_env(ros_domain_id)


class ProcessGroup:
    """Child processes started by a test, each in its own session; all are killed at teardown."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def start(self, args: list[str], env: dict[str, str], **kw) -> subprocess.Popen:
        kw.setdefault("stdout", subprocess.PIPE)
        kw.setdefault("stderr", subprocess.PIPE)
        kw.setdefault("text", True)
        proc = subprocess.Popen(args, env=env, cwd=str(REPO), start_new_session=True, **kw)
        self.procs.append(proc)
        return proc

    def stop_all(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        for proc in self.procs:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait(timeout=5)


@pytest.fixture
def procs() -> Iterator[ProcessGroup]:
    """Start child processes with `procs.start([...], env)`; they are always killed when the test ends."""
    group = ProcessGroup()
    try:
        yield group
    finally:
        group.stop_all()


@pytest.fixture(scope="session")
def plate_demo_bag(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The plate case of `hexa demo --record-images` for 4.2 s of sim time (its START included), recorded once for
    the replay tests: the graph's outputs and its sensor inputs, both cameras included (the observer's ζ estimator
    starts from the camera's plate pose)."""
    pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
    from rosdomain import held_ros_domain

    from hexa_bringup.demo_run import run_case
    from hexa_bringup.rosenv import ros_env as make_env

    out = tmp_path_factory.mktemp("plate_demo")
    with held_ros_domain(range(98, 0, -1)) as domain:       # held while the graph records
        run = run_case("plate", out, make_env(domain), duration=4.2, status_every=1e9, record_images=True)
    assert (run.bag / "metadata.yaml").exists(), f"no bag recorded (rc {run.returncode}, logs {run.log_dir})"
    yield run.bag
    shutil.rmtree(out, ignore_errors=True)          # images: hundreds of MB


#: fixtures that start ROS processes or hold a ROS domain: a test using one is `ros` and `slow` (left out of
#: `make check`; `make test` runs the `ros` tests one at a time, except the modules marked `ros_parallel`, which run on
#: two workers with the others)
SLOW_FIXTURES = frozenset({"ros_env", "ros_domain_id", "module_ros_domain_id", "procs", "plate_demo_bag"})


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test that starts ROS processes as `ros` and `slow`; heavier ROS-free tests carry `slow`
    themselves."""
    for item in items:
        if SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.ros)
            item.add_marker(pytest.mark.slow)

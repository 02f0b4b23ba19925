"""Fast DDS shared-memory files (hexa_ros.shm, `hexa doctor`): a living participant's segment is in use and kept; once
its process is killed (SIGKILL: no chance to close it) the segment is stale, its RAM counted, and removing the stale
files takes it away; `hexa doctor` warns about stale files and `--clean-shm` removes them."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from hexa_ros import shm

pytestmark = pytest.mark.ros   # reads and cleans the machine's /dev/shm: one at a time, beside no other ROS test

PARTICIPANT = """
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("shm_probe")
node.create_publisher(String, "shm_probe", 10)
print("up", flush=True)
rclpy.spin(node)
"""


def _segments() -> set[str]:
    return {p.name for p in shm.SHM_DIR.glob("fastrtps_*") if len(p.name) == len("fastrtps_") + 16}


def test_a_killed_participants_segment_is_stale_and_removed_a_living_ones_is_kept(procs, ros_env):
    before = _segments()
    proc = procs.start([sys.executable, "-c", PARTICIPANT], ros_env)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "up", proc.stderr.read() if proc.stderr else ""
    deadline = time.monotonic() + 20.0
    while not (mine := _segments() - before) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert mine, "the participant made no shared-memory segment (is hexa's DDS profile in use?)"

    stale = {p.name for p in shm.scan().stale}
    assert not stale & mine and not stale & {f"{m}_el" for m in mine}
    shm.remove_stale()
    assert all((shm.SHM_DIR / m).exists() for m in mine)       # in use: kept

    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    report = shm.scan()
    stale = {p.name for p in report.stale}
    assert mine <= stale and {f"{m}_el" for m in mine} <= stale
    assert report.stale_owners >= len(mine) and report.stale_bytes > 0    # the segment held RAM
    shm.remove_stale()
    assert not any((shm.SHM_DIR / m).exists() or (shm.SHM_DIR / f"{m}_el").exists() for m in mine)


def test_doctor_warns_about_stale_shared_memory_and_cleans_it(ros_env):
    name = "fastrtps_0123456789abcdef"
    files = [shm.SHM_DIR / name, shm.SHM_DIR / f"{name}_el"]
    try:
        files[0].write_bytes(b"\0" * 8192)
        files[1].write_bytes(b"")

        def doctor(*extra: str) -> dict:
            r = subprocess.run([sys.executable, "-m", "hexa_bringup.cli", "doctor", "--json", "--wait", "0", *extra],
                               env=ros_env, capture_output=True, text=True, timeout=60)
            assert r.stdout, r.stderr
            return {c["name"]: c for c in json.loads(r.stdout)["checks"]}["dds shared memory"]

        check = doctor()
        assert check["state"] == "warn" and "--clean-shm" in check["detail"] and all(f.exists() for f in files)
        check = doctor("--clean-shm")
        assert check["state"] == "ok" and "removed" in check["detail"] and not any(f.exists() for f in files)
    finally:
        for f in files:
            f.unlink(missing_ok=True)

"""hexa's Fast DDS profile lets best-effort 640x480 RGB frames through between processes (the default 512 KB
shared-memory segment is smaller than one frame and loses most of them)."""
from __future__ import annotations

import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

from hexa_bringup.rosenv import PROFILE, ros_env as make_env  # noqa: E402


def test_profile_file_is_shipped_and_sets_a_large_shared_memory_segment():
    text = PROFILE.read_text()
    assert "<segment_size>33554432</segment_size>" in text and "<type>SHM</type>" in text


def test_rosenv_refuses_an_out_of_range_domain_id():
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
        make_env(500)


def test_best_effort_vga_rgb_frames_arrive_intact_across_processes_with_the_profile(procs, ros_env):
    sub = procs.start([sys.executable, "test/image_peer.py", "sub", "9"], ros_env)
    pub = procs.start([sys.executable, "test/image_peer.py", "pub", "90"], ros_env)
    pub.wait(timeout=60)
    out, err = sub.communicate(timeout=60)
    received = int(out.strip().splitlines()[-1])
    assert received >= 80, f"only {received}/90 frames arrived: {err[-500:]}"

"""Across machines: the graph is DDS, so it spans hosts. Two network namespaces joined by a veth pair stand in for
two PCs; messages published on one arrive on the other, over the veth link (its byte counters prove the path)."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

from roundtrip_peer import MESSAGES  # noqa: E402

PY = sys.executable


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check, timeout=20)


@pytest.fixture
def two_hosts(ros_domain_id):
    """Namespaces hexa_a<D>/hexa_b<D> with veth 10.231.<D>.1/.2; skipped where namespaces cannot be created."""
    if shutil.which("ip") is None:
        pytest.skip("iproute2 `ip` not installed; cannot create network namespaces")
    d = ros_domain_id
    a, b = f"hexa_a{d}", f"hexa_b{d}"
    r = _ip("netns", "add", a, check=False)
    if r.returncode != 0:
        pytest.skip(f"cannot create network namespaces here (needs root/CAP_SYS_ADMIN): {r.stderr.strip()}")
    try:
        _ip("netns", "add", b)
        _ip("link", "add", f"hxa{d}", "type", "veth", "peer", "name", f"hxb{d}")
        _ip("link", "set", f"hxa{d}", "netns", a)
        _ip("link", "set", f"hxb{d}", "netns", b)
        _ip("-n", a, "addr", "add", f"10.231.{d}.1/24", "dev", f"hxa{d}")
        _ip("-n", b, "addr", "add", f"10.231.{d}.2/24", "dev", f"hxb{d}")
        for ns, dev in ((a, f"hxa{d}"), (b, f"hxb{d}")):
            _ip("-n", ns, "link", "set", dev, "up")
            _ip("-n", ns, "link", "set", "lo", "up")
        yield a, b, f"hxb{d}"
    finally:
        _ip("netns", "del", a, check=False)
        _ip("netns", "del", b, check=False)


def _rx_bytes(ns: str, dev: str) -> int:
    out = _ip("-n", ns, "-s", "-j", "link", "show", dev).stdout
    return int(json.loads(out)[0]["stats64"]["rx"]["bytes"])


def test_every_message_type_crosses_between_two_network_namespaces_over_veth(procs, ros_domain_id, two_hosts):
    from hexa_bringup.rosenv import ros_env

    a, b, dev_b = two_hosts
    env = ros_env(ros_domain_id, localhost_only=False)  # discovery across the subnet, as between two PCs
    rx0 = _rx_bytes(b, dev_b)
    pub = procs.start(["ip", "netns", "exec", a, PY, "test/roundtrip_peer.py", "pub"], env)
    assert pub.stdout.readline().strip() == "published"
    sub = procs.start(["ip", "netns", "exec", b, PY, "test/roundtrip_peer.py", "sub", "40"], env)
    out, err = sub.communicate(timeout=90)
    received = json.loads(out.strip().splitlines()[-1])
    assert sorted(received) == sorted(MESSAGES), err
    assert _rx_bytes(b, dev_b) - rx0 > 2000, "no DDS traffic crossed the veth link"

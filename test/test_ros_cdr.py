"""hexa_ros.cdr: serialized sensor_msgs/Image read in place equals rclpy's own deserialization; bad bytes are named."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")


@pytest.mark.parametrize("frame_id, encoding, shape, dtype", [
    ("cam_top_color_optical_frame", "rgb8", (48, 64, 3), np.uint8),
    ("", "16UC1", (30, 40), np.uint16),
    ("abc", "mono8", (7, 5), np.uint8),
    ("x" * 13, "32FC1", (3, 9), np.float32),
])
def test_image_read_in_place_equals_rclpy(frame_id, encoding, shape, dtype):
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    from hexa.vision.images import numpy_to_image
    from hexa_ros.cdr import image_from_cdr

    rng = np.random.default_rng(1)
    arr = (rng.random(shape) * 200).astype(dtype)
    f = numpy_to_image(arr, encoding)
    msg = Image(height=f.height, width=f.width, encoding=f.encoding, is_bigendian=f.is_bigendian, step=f.step,
                data=f.data)
    msg.header.stamp, msg.header.frame_id = Time(sec=-3, nanosec=123_456_789), frame_id
    raw = serialize_message(msg)
    ref = deserialize_message(raw, Image)
    got = image_from_cdr(raw)
    assert (got.stamp_sec, got.stamp_nanosec, got.frame_id) == (-3, 123_456_789, frame_id)
    assert (got.height, got.width, got.encoding, got.is_bigendian, got.step) == (
        ref.height, ref.width, ref.encoding, ref.is_bigendian, ref.step)
    assert got.data.tobytes() == bytes(ref.data)
    assert np.shares_memory(got.data, np.frombuffer(raw, np.uint8)) or isinstance(raw, bytes)


@pytest.mark.parametrize("frame_id, encoding, shape, dtype", [
    ("cam_top_color_optical_frame", "rgb8", (48, 64, 3), np.uint8),
    ("", "16UC1", (30, 40), np.uint16),
    ("ab", "32FC1", (3, 9), np.float32),
])
def test_image_written_as_bytes_equals_rclpys_serialization(frame_id, encoding, shape, dtype):
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    from hexa.vision.images import ImageConversionError, fill_message
    from hexa_ros.cdr import image_to_cdr

    rng = np.random.default_rng(2)
    arr = (rng.random((shape[0], shape[1] + 3, *shape[2:])) * 200).astype(dtype)[:, 2:-1]   # not contiguous
    msg = fill_message(Image(), arr, encoding)
    msg.header.stamp, msg.header.frame_id = Time(sec=7, nanosec=5), frame_id
    ours, ref = image_to_cdr(7, 5, frame_id, arr, encoding), serialize_message(msg)
    assert len(ours) == len(ref) and deserialize_message(ours, Image) == msg   # rclpy's padding bytes are arbitrary
    with pytest.raises(ImageConversionError, match="does not fit"):
        image_to_cdr(7, 5, frame_id, arr.astype(np.float64), encoding)


def test_truncated_or_foreign_bytes_are_refused_naming_why():
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image

    from hexa_ros.cdr import CdrError, image_from_cdr

    raw = serialize_message(Image(height=2, width=300, encoding="mono8", step=300, data=bytes(600)))
    with pytest.raises(CdrError, match="does not fit"):
        image_from_cdr(raw[:400])                      # cut inside the pixels
    for cut in range(5, 40):                           # cut inside every field before them
        with pytest.raises(CdrError, match="does not fit|ends inside"):
            image_from_cdr(raw[:cut])
    with pytest.raises(CdrError, match="representation"):
        image_from_cdr(b"\x00\x07\x00\x00" + raw[4:])
    with pytest.raises(CdrError, match="shorter"):
        image_from_cdr(b"\x00")


def test_driver_streams_read_in_place_equal_rclpy():
    from builtin_interfaces.msg import Time
    from hexa_msgs.msg import MotorCurrents
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from hexa_ros.cdr import joint_state_from_cdr, motor_currents_from_cdr

    js = JointState(name=[f"arm_{i}" for i in (3, 1, 2, 6, 5, 4)], position=[0.1 * k for k in range(6)],
                    effort=[-0.5 * k for k in range(6)])
    js.header.stamp, js.header.frame_id = Time(sec=12, nanosec=5), "base"
    t, names, pos, vel, eff = joint_state_from_cdr(serialize_message(js))
    assert (t, names) == (12 + 5e-9, list(js.name)) and vel.size == 0
    assert pos.tolist() == list(js.position) and eff.tolist() == list(js.effort)
    js.velocity, js.header.frame_id, js.name = [1.5] * 6, "a_longer_frame", [f"j{k}" for k in range(6)]
    _t, names, pos, vel, eff = joint_state_from_cdr(serialize_message(js))
    assert names == list(js.name) and vel.tolist() == [1.5] * 6 and eff.tolist() == list(js.effort)
    mc = MotorCurrents(current=[0.25 * k - 1 for k in range(6)], raw=[512 + k for k in range(6)], sequence=77,
                       board_time_us=4_000_000_123, gaps=2)
    mc.header.stamp, mc.header.frame_id = Time(sec=3, nanosec=999), "b"
    raw = serialize_message(mc)
    t, cur, board, setpoint = motor_currents_from_cdr(raw)
    assert (t, board) == (3 + 999e-9, 4_000_000_123) and cur.tolist() == list(mc.current) and setpoint.size == 0
    # a message recorded before the set-point field existed ends after `gaps` (the 72 bytes from the currents on
    # keep it 8-aligned: no padding): read as no set-points, and `hexa play` sends it with the empty field appended
    end = 4 + 8 + 4 + len("b") + 1
    end += (-(end - 4)) % 8 + 72
    old = raw[:end]
    assert motor_currents_from_cdr(old)[2] == board
    assert motor_currents_from_cdr(old)[3].size == 0
    from rclpy.serialization import deserialize_message

    from hexa_ros.cdr import motor_currents_with_setpoint_field
    assert deserialize_message(motor_currents_with_setpoint_field(old), MotorCurrents) == mc
    assert motor_currents_with_setpoint_field(raw) is raw
    mc.setpoint = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6]
    _t, cur, board, setpoint = motor_currents_from_cdr(serialize_message(mc))
    assert board == 4_000_000_123 and cur.tolist() == list(mc.current) and setpoint.tolist() == list(mc.setpoint)


@pytest.mark.parametrize("n", [0, 1, 10])
def test_zeta_estimates_written_as_bytes_equal_rclpy_and_read_back(n):
    from hexa_msgs.msg import ZetaEstimates
    from rclpy.serialization import deserialize_message, serialize_message

    from hexa_ros.cdr import CdrError, zeta_estimates_from_cdr, zeta_estimates_to_cdr

    rng = np.random.default_rng(n)
    times = (100.0 + 1e-3 * np.arange(n)).tolist()
    zeta, zeta_dot, tau = (rng.normal(size=6 * n).tolist() for _ in range(3))
    raw = zeta_estimates_to_cdr(100, 5_000, times, zeta, zeta_dot, tau)
    m = ZetaEstimates(time=times, zeta=zeta, zeta_dot=zeta_dot, tau=tau)
    m.header.stamp.sec, m.header.stamp.nanosec = 100, 5_000
    assert deserialize_message(raw, ZetaEstimates) == m
    for buf in (raw, serialize_message(m)):
        t, z, zd, ta = zeta_estimates_from_cdr(buf)
        assert t.tolist() == times and z.shape == zd.shape == ta.shape == (n, 6)
        assert (z.ravel().tolist(), zd.ravel().tolist(), ta.ravel().tolist()) == (zeta, zeta_dot, tau)
    m.tau = tau[:-1] if n else [1.0]
    with pytest.raises(CdrError, match="6 per time"):
        zeta_estimates_from_cdr(serialize_message(m))


@pytest.mark.parametrize("frame_id", ["base", "", "plate_x", "abcdefgh"])
def test_observer_outputs_written_as_bytes_deserialize_to_the_same_messages(frame_id):
    """residual_to_cdr / joint_state_to_cdr against rclpy: the bytes deserialize to messages equal field by field
    to those built as objects (padding bytes may differ: Fast CDR leaves them unset)."""
    from builtin_interfaces.msg import Time
    from hexa_msgs.msg import Residual
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    from hexa_ros.cdr import joint_state_to_cdr, residual_to_cdr

    rng = np.random.default_rng(len(frame_id))
    r, thr, st, sth = (rng.normal(size=6).tolist() for _ in range(4))
    force, torque = rng.normal(size=3).tolist(), rng.normal(size=3).tolist()
    over, servo_over = [bool(v) for v in rng.integers(0, 2, 6)], [bool(v) for v in rng.integers(0, 2, 6)]
    m = Residual(r=r, threshold=thr, over=over, servo_torque=st, servo_threshold=sth, servo_over=servo_over,
                 in_collision=True)
    m.header.stamp, m.header.frame_id = Time(sec=1_700_000_000, nanosec=123_456_789), frame_id
    m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = force
    m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = torque
    raw = residual_to_cdr(1_700_000_000, 123_456_789, frame_id, r, force, torque, thr, over, st, sth, servo_over,
                          True)
    assert len(raw) == len(serialize_message(m))
    assert deserialize_message(raw, Residual) == m
    names = [f"arm_{i}" for i in range(1, 7)]
    for velocity in ([], rng.normal(size=6).tolist()):
        js = JointState(name=names, position=r, velocity=velocity, effort=st)
        js.header.stamp, js.header.frame_id = Time(sec=7, nanosec=8), frame_id
        assert deserialize_message(joint_state_to_cdr(7, 8, frame_id, names, r, velocity, st), JointState) == js


@pytest.mark.parametrize("frame_id", ["base", "", "abc"])
def test_driver_streams_written_as_bytes_deserialize_to_the_same_messages(frame_id):
    """motor_currents_to_cdr against rclpy, with and without set-points: the same message, and the observer's reader
    takes back what was written."""
    from builtin_interfaces.msg import Time
    from hexa_msgs.msg import MotorCurrents
    from rclpy.serialization import deserialize_message, serialize_message

    from hexa_ros.cdr import motor_currents_from_cdr, motor_currents_to_cdr

    rng = np.random.default_rng(len(frame_id))
    cur, raw = rng.normal(size=6).tolist(), [int(v) for v in rng.integers(0, 1024, 6)]
    for setpoint in ([], rng.normal(size=6).tolist()):
        m = MotorCurrents(current=cur, raw=raw, sequence=4_000_000_000, board_time_us=123_456, gaps=7,
                          setpoint=setpoint)
        m.header.stamp, m.header.frame_id = Time(sec=1_700_000_000, nanosec=5), frame_id
        data = motor_currents_to_cdr(1_700_000_000, 5, frame_id, cur, raw, 4_000_000_000, 123_456, 7, setpoint)
        if setpoint:   # an empty sequence: Fast CDR pads to its elements' alignment anyway, 4 bytes more
            assert len(data) == len(serialize_message(m))
        assert deserialize_message(data, MotorCurrents) == m
        t, c, board_us, sp = motor_currents_from_cdr(data)
        assert (t, c.tolist(), board_us, sp.tolist()) == (1_700_000_000 + 5e-9, cur, 123_456, setpoint)

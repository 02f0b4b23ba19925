"""Message fields <-> the core's numpy values: joint vectors, poses (plain numpy on message fields)."""
from __future__ import annotations

from typing import Any

import numpy as np

from hexa.rotations import matrix_from_quaternion, quaternion_from_matrix

#: the Hexa's servo (arm) joints, in the description's chain order
JOINT_NAMES = tuple(f"arm_{i}" for i in range(1, 7))
#: the 3UPS+RPU's prismatic limbs
UPSRPU_JOINTS = ("limb_1", "limb_2", "limb_3", "limb_4")


def ordered_values(msg_names: Any, vals: Any, names: tuple[str, ...] = JOINT_NAMES) -> np.ndarray | None:
    """`vals` (one per name of `msg_names`) ordered as `names` (in message order when the message has no names);
    None when the names or lengths do not fit."""
    if len(vals) != len(names):
        return None
    if not len(msg_names) or tuple(msg_names) == names:
        return np.asarray(vals, dtype=float)
    if len(msg_names) != len(names) or set(msg_names) != set(names):
        return None
    idx = {n: k for k, n in enumerate(msg_names)}
    return np.asarray([vals[idx[n]] for n in names], dtype=float)


def ordered_joints(msg: Any, field: str, names: tuple[str, ...] = JOINT_NAMES) -> np.ndarray | None:
    """The values of `field` of a sensor_msgs/JointState ordered as `names` by msg.name (in message order when the
    message has no names); None when the names or lengths do not fit."""
    return ordered_values(msg.name, getattr(msg, field), names)


def transform_from_pose_msg(pose: Any) -> np.ndarray:
    """4x4 transform of a geometry_msgs/Pose.

    Raises:
        ValueError: the orientation is zero or not finite.
    """
    return _transform(pose.orientation, pose.position)


def transform_from_transform_msg(transform: Any) -> np.ndarray:
    """4x4 transform T_parent_child of a geometry_msgs/Transform (e.g. TransformStamped.transform on /tf).

    Raises:
        ValueError: the rotation is zero or not finite.
    """
    return _transform(transform.rotation, transform.translation)


def _transform(q: Any, p: Any) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion(q.x, q.y, q.z, q.w)
    T[:3, 3] = (p.x, p.y, p.z)
    return T


def fill_pose_msg(pose: Any, R: np.ndarray, t: np.ndarray) -> Any:
    """Write rotation R and translation t into a geometry_msgs/Pose and return it."""
    q = quaternion_from_matrix(R)
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in t)
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = (float(v) for v in q)
    return pose


def wrench_stamped(frame_id: str, stamp: Any, force: Any, torque: Any = (0.0, 0.0, 0.0)) -> Any:
    """geometry_msgs/WrenchStamped of force (N) and torque (N·m), both expressed in `frame_id`."""
    from geometry_msgs.msg import WrenchStamped

    w = WrenchStamped()
    w.header.stamp, w.header.frame_id = stamp, frame_id
    w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = (float(v) for v in force)
    w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = (float(v) for v in torque)
    return w


def sim_truth_messages(state: Any, truth: Any, link_codes: dict[str, int]) -> dict[str, Any]:
    """The simulator's ground truth as the messages of its `sim/*_truth` topics, in frame `base`: `wrench_truth`
    (WrenchStamped at the contact point), `contact_truth` (hexa_msgs/Contact, confidence 1 in contact),
    `plate_pose_truth` (PoseStamped), `joint_states_truth` (JointState: ζ, ζ̇, τ); stamped with the truth's time.

    Args:
        state, truth: hexa.sim.SimState and GroundTruth of one instant.
        link_codes: link name → hexa_msgs/Contact link code (hexa.sim.simulator.LINK_CODES).
    """
    from geometry_msgs.msg import PoseStamped
    from hexa_msgs.msg import Contact
    from sensor_msgs.msg import JointState

    from hexa.kinematics.hexa6rus import rotation_zyx
    from hexa_ros.stamps import to_stamp

    st = to_stamp(truth.time)
    c = Contact(link=link_codes[truth.link], chain=int(truth.chain), pixel_u=-1.0, pixel_v=-1.0, camera="",
                confidence=1.0 if truth.in_contact else 0.0)
    c.point.x, c.point.y, c.point.z = (float(v) for v in truth.point)
    ps = PoseStamped()
    fill_pose_msg(ps.pose, rotation_zyx(*state.pose[3:]), state.pose[:3])
    js = JointState(name=list(JOINT_NAMES), position=state.zeta.tolist(), velocity=state.zeta_dot.tolist(),
                    effort=state.tau.tolist())
    for m in (c, ps, js):
        m.header.stamp, m.header.frame_id = st, "base"
    return {"wrench_truth": wrench_stamped("base", st, truth.force, truth.torque), "contact_truth": c,
            "plate_pose_truth": ps, "joint_states_truth": js}


def hexa_pose_from_msg(pose: Any) -> np.ndarray:
    """Hexa pose (x, y, z, α, β, γ) (Z-Y-X, seed 000 eq 38) of a geometry_msgs/Pose.

    Raises:
        ValueError: the orientation is zero or not finite.
    """
    from hexa.rotations import pose6_from_transform

    return pose6_from_transform(transform_from_pose_msg(pose))


def pose_fields(pose: Any) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """(position, quaternion x y z w) of a geometry_msgs/Pose as sent: not normalised, not checked (hexa.pose_check
    checks them)."""
    p, q = pose.position, pose.orientation
    return (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)


def upsrpu_pose_to_msg_fields(X: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """(position, quaternion) of the 3UPS+RPU pose X = (x_m, z_m, θ, ψ) in the fixed frame."""
    from hexa.kinematics.upsrpu import rotation_yz

    q = quaternion_from_matrix(rotation_yz(X[2], X[3]))
    return (float(X[0]), 0.0, float(X[1])), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def upsrpu_pose_from_msg(pose: Any) -> np.ndarray:
    """X = (x_m, z_m, θ, ψ) of a geometry_msgs/Pose (projected on the robot's four DOF)."""
    from hexa.srm.tracking import pose_from_transform

    T = transform_from_pose_msg(pose)
    return pose_from_transform(T[:3, :3], T[:3, 3])


def points_from_pose_array(msg: Any) -> np.ndarray:
    """(N, 3) marker positions of a geometry_msgs/PoseArray (orientations ignored)."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses], dtype=float).reshape(-1, 3)

"""MJCF of the Hexa generated from its robot description (never a hand-kept copy of a dimension).

Tree: world → six arms on motor hinges at A_i (axis Z_1i of seed 000 eq 6) → rods on universal joints at B_i (two
hinges: the first parallel to the motor axis, the second perpendicular to it and to the rod) → free plate, closed
with six ball-joint equality constraints (`connect`) at the C_i. The model is assembled at a given pose of the plate
(inverse kinematics), with each motor hinge's `ref` equal to that pose's ζ_i, so qpos of `arm_i` *is* ζ_i (rad).
Servos are MuJoCo position actuators (kp, kv) with the servo's torque limit as force range; the speed limit is
applied by the simulator as a slew limit on the target. Nothing collides (contype 0): contacts are scripted wrenches.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.kinematics import hexa6rus as kin
from hexa.robots.plate import plate_outline
from hexa.sim.camera import mjcf_camera
from hexa.sim.config import SimConfig, sim_config_of

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.realism import RobotTruth

HOME_POSE = np.array([0.0, 0.0, -0.55, 0.0, 0.0, 0.0])
PARK_POS = (0.0, 0.0, 5.0)      # where unused mocap bodies (object, occluders) wait: outside every view
PUSHER_RADIUS, PUSHER_LENGTH, PUSHER_MASS = 0.015, 0.25, 0.05   # the physical-contact pusher (m, kg)
N_OCCLUDERS = 3


class MJCFError(ValueError):
    """The description cannot be turned into a model (the message names the value)."""


def _f(v: ArrayLike) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.atleast_1d(v))


def _rgba(rgb: np.ndarray, a: float = 1.0) -> str:
    return _f([*rgb, a])


def _frame_from_xz(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Rotation with first column along x and third column along the part of z orthogonal to x."""
    x = x / np.linalg.norm(x)
    z = z - (z @ x) * x
    nz = np.linalg.norm(z)
    if nz < 1e-9:
        raise MJCFError(f"axis {z.tolist()} is parallel to {x.tolist()}")
    z = z / nz
    return np.column_stack([x, np.cross(z, x), z])


def _quat(R: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).ravel())
    return q


def motor_axes(desc: HexaDescription) -> np.ndarray:
    """Unit motor axes Z_1i in base (6,3): R_Oi(α_i)·(0, 1, 0) (seed 000 eqs 4, 6); ζ_i is positive about them."""
    a = np.asarray(desc.alpha, dtype=float)
    return np.column_stack([-np.sin(a), np.cos(a), np.zeros(6)])


def _inertial(mass: float, com: np.ndarray, inertia: np.ndarray) -> str:
    I = np.asarray(inertia, dtype=float)
    if I.shape == (3, 3):
        full = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    elif I.shape == (3,):
        full = [I[0], I[1], I[2], 0.0, 0.0, 0.0]
    else:
        raise MJCFError(f"inertia must be (3,) or (3,3), got shape {I.shape}")
    return f'<inertial pos="{_f(com)}" mass="{mass:.9g}" fullinertia="{_f(full)}"/>'


def build_mjcf(desc: HexaDescription, pose: np.ndarray | None = None, config: SimConfig | None = None,
               physical_contact: bool = False, truth: RobotTruth | None = None, motor_servos: bool = False) -> str:
    """MJCF text of the Hexa of `desc`, assembled at plate `pose` [x y z α β γ] (m, rad; Z-Y-X, eq 38).

    Args:
        desc: a HexaDescription (hexa.robots.hexa_description.load_hexa()).
        pose: assembly pose (default HOME_POSE); qpos0 is consistent there (constraints exactly satisfied).
        config: simulator sections (default: read from `desc`).
        physical_contact: add the force-driven pusher (a capsule on a slide joint under a kinematic carrier) that
            touches the arms, rods and plate through MuJoCo contacts; without it nothing collides.
        truth: a hexa.sim.realism.RobotTruth: each link's mass, COM and inertia, and each arm joint's Coulomb
            friction (`frictionloss`), viscous friction (`damping`) and rotor inertia (`armature`) from it instead
            of the description (the geometry stays the description's).
        motor_servos: servos as torque motors (ctrl = the horn torque, clamped at the stall torque), for a servo law
            computed outside MuJoCo (hexa.sim.realism.ServoMechanics); else MuJoCo position actuators (kp, kv).

    Raises:
        MJCFError: an unusable dimension; UnreachablePoseError from the inverse kinematics.
    """
    cfg = config if config is not None else sim_config_of(desc)
    pose = HOME_POSE if pose is None else np.asarray(pose, dtype=float)
    zeta = kin.inverse_kinematics(desc, pose)
    A = np.asarray(desc.A, dtype=float)
    B = kin.elbows(desc, zeta)
    C = kin.plate_joints(desc, pose)
    R_p = kin.rotation_zyx(*pose[3:])
    ax = motor_axes(desc)
    ap = cfg.appearance
    l_a, l_d = float(desc.l_a), float(desc.l_d)
    for i in range(6):
        if abs(np.linalg.norm(B[i] - A[i]) - l_a) > 1e-6 or abs(np.linalg.norm(C[i] - B[i]) - l_d) > 1e-5:
            raise MJCFError(f"chain {i + 1}: inverse kinematics does not close the loop at pose {pose.tolist()}")
    mp = desc_mass_properties(desc)
    if truth is not None:
        mp["plate"] = {"mass": truth.plate.mass, "com": truth.plate.com, "inertia": truth.plate.inertia}
    servo = cfg.servo
    tau_max = float(desc.torque_max)
    lo, hi = float(desc.zeta_min), float(desc.zeta_max)

    aff = ' conaffinity="2"' if physical_contact else ""
    out: list[str] = []
    w = out.append
    w('<mujoco model="hexa">')
    w('<compiler angle="radian" autolimits="true"/>')
    w(f'<option timestep="{cfg.timestep:.9g}" integrator="Euler" gravity="0 0 -9.81" cone="elliptic">'
      + ('</option>' if physical_contact else '<flag contact="disable"/></option>'))
    w('<visual><global offwidth="640" offheight="480"/><quality shadowsize="0" offsamples="0"/>'
      '<headlight ambient="0.35 0.35 0.35" diffuse="0.55 0.55 0.55" specular="0.05 0.05 0.05"/>'
      '<map znear="0.005" zfar="40"/></visual>')
    w('<statistic extent="2" center="0 0 -0.4"/>')
    w('<default><geom contype="0" conaffinity="0" group="1"/>'
      f'<joint damping="{servo.damping:.9g}" armature="0"/></default>')
    w('<asset>')
    hexagon = plate_outline(desc)
    t2 = ap["plate_thickness"] / 2
    verts = [(*v, -t2) for v in hexagon] + [(*v, t2) for v in hexagon]
    w(f'<mesh name="plate_hex" vertex="{_f(np.ravel(verts))}"/>')
    for key in ("arm_rgb", "rod_rgb", "plate_rgb", "base_rgb", "servo_rgb", "background_rgb", "object_rgb"):
        w(f'<material name="{key[:-4]}" rgba="{_rgba(ap[key])}" specular="0.1" shininess="0.1"/>')
    for k, mk in enumerate(cfg.markers.items):
        w(f'<material name="marker_{mk.name}" rgba="{_rgba(mk.rgb)}" specular="0" emission="0.25"/>')
    w('</asset>')

    w('<worldbody>')
    w('<light name="top" pos="0 0 1.5" dir="0 0 -1" directional="true" castshadow="false" '
      'diffuse="0.45 0.45 0.45" specular="0.05 0.05 0.05"/>')
    # plain background: floor, four walls and a ceiling
    h, fz = ap["room_half_size"], ap["floor_z"]
    # a plane's third size is its rendering grid spacing: one cell, not MuJoCo's up to 200x200 quads (≈ 3 ms of
    # software rendering per camera frame); the floor's colour moves by at most one level (lighting interpolated
    # over one quad instead of many), its depth by < 2 µm
    w(f'<geom name="floor" type="plane" size="{h:.6g} {h:.6g} {2 * h:.6g}" pos="0 0 {fz:.6g}" material="background"/>')
    w(f'<geom name="ceiling" type="box" size="{h:.6g} {h:.6g} 0.01" pos="0 0 0.6" material="background"/>')
    for name, pos, size in (("wall_px", (h, 0, 0), (0.01, h, 1)), ("wall_nx", (-h, 0, 0), (0.01, h, 1)),
                            ("wall_py", (0, h, 0), (h, 0.01, 1)), ("wall_ny", (0, -h, 0), (h, 0.01, 1))):
        w(f'<geom name="{name}" type="box" size="{_f(size)}" pos="{_f(pos)}" material="background"/>')
    # base platform above the motors, servo housings, cameras and the side camera's bar
    w(f'<geom name="base" type="cylinder" size="{ap["base_radius"]:.6g} 0.005" pos="0 0 0.025" material="base"/>')
    for i in range(6):
        R = _frame_from_xz(np.cross(ax[i], [0, 0, 1.0]), ax[i])
        w(f'<geom name="servo_{i + 1}" type="box" size="0.02 0.01 0.01" pos="{_f(A[i] + [0, 0, 0.012])}" '
          f'quat="{_f(_quat(R))}" material="servo"/>')
    for cam in cfg.cameras.values():
        w(mjcf_camera(cam))
    side = cfg.cameras["cam_side"].position
    w(f'<geom name="side_bar" type="box" size="0.01 0.01 {(side[2] - fz) / 2:.6g}" '
      f'pos="{_f([side[0] * 1.03, side[1] * 1.03, (side[2] + fz) / 2 - 0.02])}" material="servo"/>')

    for i in range(6):
        n = i + 1
        x_arm = (B[i] - A[i]) / l_a
        R_arm = _frame_from_xz(x_arm, ax[i])
        w(f'<body name="arm_{n}" pos="{_f(A[i])}" quat="{_f(_quat(R_arm))}">')
        joint_extra = f'armature="{servo.armature:.9g}"'
        arm_mp, rod_mp = mp["arm"], mp["rod"]
        if truth is not None:
            joint_extra = (f'armature="{servo.armature + truth.rotor_inertia[i]:.9g}" '
                           f'damping="{servo.damping + truth.viscous[i]:.9g}" frictionloss="{truth.coulomb[i]:.9g}"')
            arm_mp = {"mass": truth.arms[i].mass, "com": truth.arms[i].com, "inertia": truth.arms[i].inertia}
            rod_mp = {"mass": truth.rods[i].mass, "com": truth.rods[i].com, "inertia": truth.rods[i].inertia}
        w(f'<joint name="arm_{n}" type="hinge" axis="0 0 1" ref="{zeta[i]:.12g}" range="{lo:.9g} {hi:.9g}" '
          f'limited="false" {joint_extra}/>')
        w(_inertial(arm_mp["mass"], arm_mp["com"], arm_mp["inertia"]))
        w(f'<geom name="arm_{n}" type="capsule" fromto="0 0 0 {l_a:.9g} 0 0" size="{ap["arm_radius"]:.6g}" '
          f'material="arm"{aff}/>')
        x_rod = (C[i] - B[i]) / l_d
        R_rod = _frame_from_xz(x_rod, ax[i])
        R_rel = R_arm.T @ R_rod
        a1 = R_rod.T @ ax[i]
        w(f'<body name="rod_{n}" pos="{l_a:.12g} 0 0" quat="{_f(_quat(R_rel))}">')
        w(f'<joint name="u1_{n}" type="hinge" axis="{_f(a1)}" damping="0"/>')
        w(f'<joint name="u2_{n}" type="hinge" axis="0 1 0" damping="0"/>')
        w(_inertial(rod_mp["mass"], rod_mp["com"], rod_mp["inertia"]))
        w(f'<geom name="rod_{n}" type="capsule" fromto="0 0 0 {l_d:.9g} 0 0" size="{ap["rod_radius"]:.6g}" '
          f'material="rod"{aff}/>')
        w(f'<site name="rod_tip_{n}" pos="{l_d:.12g} 0 0" size="0.004"/>')
        w('</body></body>')

    w(f'<body name="plate" pos="{_f(pose[:3])}" quat="{_f(_quat(R_p))}">')
    w('<freejoint name="plate"/>')
    w(_inertial(mp["plate"]["mass"], mp["plate"]["com"], mp["plate"]["inertia"]))
    w(f'<geom name="plate" type="mesh" mesh="plate_hex" material="plate"{aff}/>')
    mz = t2 + cfg.markers.thickness / 2
    for mk in cfg.markers.items:
        w(f'<geom name="marker_{mk.name}" type="cylinder" size="{cfg.markers.radius:.6g} '
          f'{cfg.markers.thickness / 2:.6g}" pos="{_f(mk.position + [0, 0, mz])}" material="marker_{mk.name}"/>')
    Cp = np.asarray(desc.C, dtype=float)
    for i in range(6):
        w(f'<site name="plate_joint_{i + 1}" pos="{_f(Cp[i])}" size="0.004"/>')
    w('</body>')

    if physical_contact:
        # pusher: kinematic carrier (mocap) + capsule sliding along the carrier's z (the push direction); it is the
        # only geom with contype 2, the robot's links the only ones with conaffinity 2
        w(f'<body name="pusher_carrier" mocap="true" pos="{_f(PARK_POS)}">'
          '<body name="pusher" gravcomp="1"><joint name="pusher_slide" type="slide" axis="0 0 1" damping="0"/>'
          f'<inertial pos="0 0 -{PUSHER_LENGTH / 2:.6g}" mass="{PUSHER_MASS:.6g}" diaginertia="1e-4 1e-4 1e-5"/>'
          f'<geom name="pusher" type="capsule" fromto="0 0 -{PUSHER_LENGTH:.6g} 0 0 -{PUSHER_RADIUS:.6g}" '
          f'size="{PUSHER_RADIUS:.6g}" material="object" contype="2" conaffinity="0" condim="3" friction="0.3"/>'
          '</body></body>')
    # external object (scripted contact) and occluders: mocap bodies, visual only
    w(f'<body name="object" mocap="true" pos="{_f(PARK_POS)}">'
      '<geom name="object" type="capsule" fromto="0 0 0 0 0 0.25" size="0.015" material="object"/></body>')
    for k in range(N_OCCLUDERS):
        w(f'<body name="occluder_{k}" mocap="true" pos="{_f(PARK_POS)}">'
          f'<geom name="occluder_{k}" type="box" size="0.03 0.02 0.01" rgba="0.5 0.4 0.3 1"/></body>')
    w('</worldbody>')

    w('<equality>')
    for i in range(6):
        w(f'<connect name="ball_{i + 1}" site1="rod_tip_{i + 1}" site2="plate_joint_{i + 1}" '
          'solref="0.002 1" solimp="0.99 0.999 0.0001"/>')
    w('</equality>')
    w('<actuator>')
    for i in range(6):
        if motor_servos:
            w(f'<motor name="servo_{i + 1}" joint="arm_{i + 1}" gear="1" ctrlrange="{-tau_max:.9g} {tau_max:.9g}"/>')
            continue
        w(f'<position name="servo_{i + 1}" joint="arm_{i + 1}" kp="{servo.kp:.9g}" kv="{servo.kv:.9g}" '
          f'forcerange="{-tau_max:.9g} {tau_max:.9g}" ctrlrange="{lo:.9g} {hi:.9g}"/>')
    if physical_contact:
        w('<motor name="pusher" joint="pusher_slide" gear="1"/>')
    w('</actuator>')
    w('</mujoco>')
    return "\n".join(out)


def desc_mass_properties(desc: HexaDescription) -> dict[str, dict[str, Any]]:
    """Mass (kg), COM (m) and inertia (kg·m², about the COM, in the link frame) of plate, arm and rod from `desc`.

    Link frames: arm — x from A_i to B_i, z the motor axis; rod — x from B_i to C_i; plate — {P}.
    """
    out = {}
    for link in ("plate", "arm", "rod"):
        li = getattr(desc, link)
        out[link] = {"mass": float(li.mass), "com": np.asarray(li.com, dtype=float),
                     "inertia": np.asarray(li.inertia, dtype=float)}
    return out

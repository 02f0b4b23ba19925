"""The bench's input bag, made by the simulator alone: the driver's two streams and both cameras of one collision
case, every message stamped with its sim time and written with that time.

A bag recorded from the live graph loses 1 kHz samples when the machine is loaded and carries the recorder's
receive times (bursts of samples on one timestamp). This one is complete and the same on every machine: the
simulator follows the case's trajectory itself (its servo set-points are what `joint_states.position` carries), the
Mega's samples are τ/K_t through the ACS712 + 10-bit ADC model with the configured ADC noise (hexa.protocol.
sensor_model; the zero offset is calibrated out, as the driver does), and the cameras render at `camera_rate_hz`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: the driver's frame and joint names; the camera topics as the simulator publishes them
CAMERAS = ("cam_top", "cam_side")


def synthesize(path: Path, case: str = "plate", stream_rate_hz: int = 1000, camera_rate_hz: float = 30.0,
               seed: int = 0, ns: str = "/hexa", progress: Callable[[str], None] | None = None) -> Path:
    """Write the bag of `case` ("plate" | "arm" | "rod", hexa_bringup.demo_run.CASES) to `path` (must not exist).

    Raises:
        hexa_bringup.bag.BagError: `path` exists or cannot be written.
        ValueError: an unknown case or a stream rate that does not divide the simulator's 1 kHz step.
    """
    from hexa.protocol.driver_core import load_driver_config
    from hexa.protocol.sensor_model import CurrentSensorModel
    from hexa.sim import Simulator
    from hexa.vision.images import numpy_to_image
    from hexa_bringup.bag import BagRecorder, typestore
    from hexa_bringup.demo_run import CASES, LEAD_IN

    if case not in CASES:
        raise ValueError(f"unknown case {case!r}; use one of {sorted(CASES)}")
    scenario, _trajectory, duration = CASES[case]
    sim = Simulator(seed=seed, scenario=scenario, cameras=True, lead_in=LEAD_IN)
    every = int(round(1.0 / (stream_rate_hz * sim.timestep)))
    if every < 1 or abs(every * stream_rate_hz * sim.timestep - 1.0) > 1e-9:
        raise ValueError(f"stream_rate_hz {stream_rate_hz} must divide the simulator's {1 / sim.timestep:g} Hz step")
    sensor = CurrentSensorModel.from_dict(load_driver_config().get("sensor", {}))
    noise = float(sim.config.current_noise_counts)
    rng = np.random.default_rng([seed, 7])
    k_t = float(sim.desc.K_t)
    names = [f"arm_{i}" for i in range(1, 7)]
    t_end = LEAD_IN + duration
    cam_period = 1.0 / camera_rate_hz
    store = typestore()
    ty = store.types
    Time, Header = ty["builtin_interfaces/msg/Time"], ty["std_msgs/msg/Header"]
    Image, CameraInfo, JointState = (ty[f"sensor_msgs/msg/{n}"] for n in ("Image", "CameraInfo", "JointState"))
    MotorCurrents, Roi = ty["hexa_msgs/msg/MotorCurrents"], ty["sensor_msgs/msg/RegionOfInterest"]

    def header(t: float, frame: str):
        ns_ = int(round(t * 1e9))
        return Header(stamp=Time(sec=ns_ // 1_000_000_000, nanosec=ns_ % 1_000_000_000), frame_id=frame)

    def image(arr: np.ndarray, encoding: str, t: float, frame: str):
        f = numpy_to_image(arr, encoding)
        return Image(header=header(t, frame), height=f.height, width=f.width, encoding=f.encoding,
                     is_bigendian=int(f.is_bigendian), step=f.step, data=np.frombuffer(f.data, np.uint8))

    infos = {}
    for c in CAMERAS:
        model = sim.camera_model(c)
        f = model.camera_info_fields()
        infos[c] = (f, model.frame_id)

    def info_msg(c: str, t: float):
        f, frame = infos[c]
        return CameraInfo(header=header(t, frame), height=int(f["height"]), width=int(f["width"]),
                          distortion_model=f["distortion_model"], d=np.asarray(f["d"], float),
                          k=np.asarray(f["k"], float), r=np.asarray(f["r"], float), p=np.asarray(f["p"], float),
                          binning_x=0, binning_y=0, roi=Roi(x_offset=0, y_offset=0, height=0, width=0,
                                                            do_rectify=False))

    def cdr(msg) -> bytes:
        return bytes(store.serialize_cdr(msg, msg.__msgtype__))
    p = ns.rstrip("/")
    topics = {"joint_states": "sensor_msgs/msg/JointState", "motor_currents": "hexa_msgs/msg/MotorCurrents"}
    for c in CAMERAS:
        topics.update({f"{c}/color/image_raw": "sensor_msgs/msg/Image",
                       f"{c}/aligned_depth_to_color/image_raw": "sensor_msgs/msg/Image",
                       f"{c}/color/camera_info": "sensor_msgs/msg/CameraInfo"})

    with BagRecorder(path) as bag:
        for topic, msgtype in topics.items():
            bag.add_topic(f"{p}/{topic}", msgtype, reliable=not topic.startswith("cam_"))

        def cameras() -> None:
            t = sim.time
            t_ns = int(round(t * 1e9))
            for c in CAMERAS:
                rgb, depth = sim.render(c)
                frame = infos[c][1]
                bag.write(f"{p}/{c}/color/image_raw", t_ns, cdr(image(rgb, "rgb8", t, frame)))
                bag.write(f"{p}/{c}/aligned_depth_to_color/image_raw", t_ns, cdr(image(depth, "16UC1", t, frame)))
                bag.write(f"{p}/{c}/color/camera_info", t_ns, cdr(info_msg(c, t)))

        cameras()
        next_cam, seq, next_note = cam_period, 0, 1.0
        while sim.time < t_end - 1e-9:
            sim.step(every)
            s = sim.state()
            counts = sensor.counts_from_current(s.tau / k_t + noise * sensor.amps_per_count * rng.standard_normal(6))
            amps = sensor.current_from_counts(counts) - sensor.current_from_counts(sensor.counts_from_current(0.0))
            t_ns = int(round(s.time * 1e9))
            m = MotorCurrents(header=header(s.time, "base"), current=amps.astype(float),
                              raw=counts.astype(np.uint16), sequence=seq & 0xFFFFFFFF,
                              board_time_us=int(round(s.time * 1e6)) & 0xFFFFFFFF, gaps=0,
                              setpoint=np.asarray(s.targets, float))
            js = JointState(header=header(s.time, "base"), name=names, position=np.asarray(s.targets, float),
                            velocity=np.zeros(0), effort=k_t * amps)
            bag.write(f"{p}/motor_currents", t_ns, cdr(m))
            bag.write(f"{p}/joint_states", t_ns, cdr(js))
            seq += 1
            if sim.time + 1e-9 >= next_cam:
                cameras()
                next_cam += cam_period
            if progress is not None and sim.time >= next_note:
                progress(f"synthesizing the bench bag: {sim.time:.1f} of {t_end:.1f} s of sim time")
                next_note = math.floor(sim.time) + 1.0
    sim.close()
    return path

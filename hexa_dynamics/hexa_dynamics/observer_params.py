"""The observer node's parameters (hexa_ros.node.Param): defaults from the core's configurations, units, ranges, and
which ones a running node takes (the rest are read-only: a set is refused with the reason)."""
from __future__ import annotations

from hexa.dynamics.cusum import DETECTORS, CusumConfig
from hexa.dynamics.monitoring import WatchConfig
from hexa.dynamics.observer import ObserverConfig
from hexa.estimation import EstimatorConfig
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param
from hexa_ros.realtime import REALTIME_PRIORITY, REALTIME_PRIORITY_PARAM

#: the parameters the observer applies on a running node (hexa.dynamics.monitor.CollisionMonitor.configure)
RUNTIME = ("gains", "thresholds", "servo_thresholds", "release_ratio", "min_duration", "cusum_drift", "cusum_alarm",
           "cusum_velocity_gain", "cusum_accel_gain", "cusum_accel_tau", "cusum_baseline_tau", "accel_sigma",
           "torque_sigma",
           "camera_sigma", "bias_walk", "saturation", "stall_sigma", "reseed_distance", "calibration_duration",
           "marker_rate_hz", "marker_scale", "pose_estimate_rate_hz", "tf_rate_hz", "zeta_batch_period")


def observer_parameters() -> dict[str, Param]:
    """Name → Param of every observer parameter (hexa_bringup/config/hexa_params.yaml has the same defaults)."""
    o, e, w, c = ObserverConfig(), EstimatorConfig(), WatchConfig(), CusumConfig()
    def six(v: tuple) -> list[float]:
        return [float(x) for x in v]

    table = {
        DESCRIPTION: DESCRIPTION_PARAM,
        REALTIME_PRIORITY: REALTIME_PRIORITY_PARAM,
        "zeta_source": Param("estimator", "estimator (hobby servos: joint_states.position is the command) | measured",
                             choices=("estimator", "measured")),
        "time_source": Param("auto", "sample time: auto (board clock of motor_currents when present) | board | stamp",
                             choices=("auto", "board", "stamp")),
        "board_clock": Param("auto", "board time: auto (= sim time under use_sim_time) | sim | track",
                             choices=("auto", "sim", "track")),
        "gains": Param(six(o.gains), "observer gains K_j (1/s), axes fx fy fz mx my mz", range=(0.0, 1e4)),
        "thresholds": Param(six(o.thresholds), "r_low per axis (N, N*m)"),
        "servo_thresholds": Param(six(o.servo_thresholds), "threshold on the residual as servo torques (N*m; 0 = off)"),
        "release_ratio": Param(float(o.release_ratio), "an axis releases below release_ratio * r_low (hysteresis)"),
        "min_duration": Param(float(o.min_duration), "s over threshold before START, all released before END"),
        "detector": Param("threshold", "collision detector: threshold (|r| over the thresholds for min_duration) | "
                          "cusum (sequential test on the residual whitened by the thresholds, a slow baseline and "
                          "the motion; docs/detectors.md)", choices=DETECTORS),
        "cusum_drift": Param(float(c.drift), "cusum: drift nu subtracted from the whitened residual (threshold units)",
                             range=(0.0, 10.0)),
        "cusum_alarm": Param(float(c.alarm), "cusum: START when a channel's sum reaches this (threshold units * s)",
                             range=(1e-4, 10.0)),
        "cusum_velocity_gain": Param(float(c.velocity_gain), "cusum: thresholds * (1 + this * max|zeta_dot| + ...) "
                                     "(s/rad)", range=(0.0, 100.0)),
        "cusum_accel_gain": Param(float(c.accel_gain), "cusum: thresholds * (1 + ... + this * max|zeta_ddot|) "
                                  "(s^2/rad)", range=(0.0, 100.0)),
        "cusum_accel_tau": Param(float(c.accel_tau), "cusum: time constant of zeta_ddot from zeta_dot (s)",
                                 range=(1e-4, 10.0)),
        "cusum_baseline_tau": Param(float(c.baseline_tau), "cusum: time constant of each channel's slow baseline "
                                    "(model error), followed only without evidence of a contact (s; 0 = off)",
                                    range=(0.0, 60.0)),
        "max_gap": Param(float(o.max_gap), "s; a longer joint_states spacing restarts the integration",
                         range=(1e-3, 10.0)),
        "pose_delay": Param(0.5, "s; camera poses are applied at image stamp + pose_delay", range=(0.0, 5.0)),
        "accel_sigma": Param(float(e.accel_sigma), "estimator: white-acceleration density (rad/s^1.5)"),
        "torque_sigma": Param(float(e.torque_sigma), "estimator: servo-measurement noise as torque (N*m)"),
        "camera_sigma": Param(float(e.camera_sigma), "estimator: noise of zeta from a camera pose (rad); 0 = off"),
        "bias_walk": Param(float(e.bias_walk), "estimator: random walk of the servo-model offset (rad/sqrt(s))"),
        "saturation": Param(float(e.saturation), "estimator: |tau| > saturation * torque_max = stalled servo"),
        "stall_sigma": Param(float(e.stall_sigma), "estimator: a stalled servo's sample as a weak measurement (rad)"),
        "command_delay": Param(0.0, "s from the commanded angle to the servo's set-point", range=(0.0, 1.0)),
        "reseed_distance": Param(0.005, "m; a camera pose this far from the tracked pose re-seeds the tracking"),
        "calibration_duration": Param(1.0, "s averaged by ~/reset with recalibrate=true", range=(0.01, 60.0)),
        "marker_rate_hz": Param(10.0, "residual force arrow rate on `markers`", range=(0.0, 1000.0)),
        "marker_scale": Param(0.02, "arrow length per newton (m/N)", range=(0.0, 1.0)),
        "pose_estimate_rate_hz": Param(100.0, "plate_pose_estimate rate (Hz of sample time)", range=(0.001, 1000.0)),
        "tf_rate_hz": Param(30.0, "/tf rate of the plate, arm and rod frames (Hz of sample time)",
                            range=(0.001, 1000.0)),
        "zeta_batch_period": Param(0.01, "s of sample time per message on `zeta_estimates` (the rnea node's input; "
                                   "sent at once on a collision event); 0 = one message per sample", range=(0.0, 0.1)),
        "monitoring_timeout": Param(w.timeout, "s (node clock) without a fresh residual before `monitoring` is LOST",
                                    range=(0.005, 10.0)),
        "monitoring_pose_timeout": Param(w.pose_timeout, "s without a plate pose the estimator used before LOST "
                                         "(zeta_source estimator with camera_sigma > 0)", range=(0.05, 60.0)),
        "monitoring_wall_timeout": Param(w.wall_timeout, "wall s without a fresh residual while the node's clock "
                                         "stands still (sim time) before DEGRADED 'clock stalled'", range=(0.05, 60.0)),
        "monitoring_settle_time": Param(w.settle_time, "s of fresh residuals before OK (start-up, reset, after LOST)",
                                        range=(0.0, 10.0)),
        "frame_id": Param("base", "frame of residual, collision and plate_pose_estimate")}
    return {k: Param(p.default, p.description, k in RUNTIME, p.range, p.choices) for k, p in table.items()}

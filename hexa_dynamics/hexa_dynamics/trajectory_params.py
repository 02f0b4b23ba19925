"""The trajectory node's parameters (hexa_ros.node.Param): the fields of hexa.trajectory_runner.TrajectorySettings and
`description`, with units and ranges; all read at start-up (read-only)."""
from __future__ import annotations

from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param

PARAMETERS = {
    "trajectory": Param("circle", "circle | helix | ellipse (seed 000 eqs 37, 40, 41), random:SEED (the random "
                                  "trajectory of hexa eval), file (the pose file `file`), or names joined by '+' "
                                  "played in turn (circle+helix+ellipse)"),
    "file": Param("", "CSV of t x y z alpha beta gamma (SI) for trajectory=file"),
    "rate_hz": Param(100.0, "joint_commands per second", range=(1.0, 1000.0)),
    "start_delay": Param(1.0, "s after the first clock reading before the trajectory starts", range=(0.0, 3600.0)),
    "start_time": Param(-1.0, "s, clock time of trajectory time 0; < 0 = use start_delay", range=(-1.0, 1e9)),
    "loop": Param(False, "restart at the end"),
    "loop_blend": Param(2.0, "s; with loop, cross-fade onto the next cycle (the helix ends 5 cm higher)",
                        range=(0.0, 60.0)),
    "collision_policy": Param("hold", "on collision START; resume with ~/resume",
                              choices=("hold", "retract", "ignore")),
    "retract_distance": Param(0.02, "m along the residual force (policy retract)", range=(0.0, 0.1)),
    "retract_time": Param(0.5, "s the retraction takes", range=(0.01, 10.0)),
    "max_step": Param(0.03, "s; most trajectory time per command: a late node pauses, never jumps (0 = no limit)",
                      range=(0.0, 1.0)),
    "start_blend": Param(1.0, "s; blend from rest onto the trajectory (0 = velocity step)", range=(0.0, 10.0)),
    "approach_speed": Param(0.0, "rad/s; > 0: wait for plate_pose, move from it to the start pose at most this fast "
                                 "(0 = off)", range=(0.0, 2.0)),
    "approach_tolerance": Param(0.02, "rad; no approach when every arm is this close to the start pose",
                                range=(0.0, 1.0)),
    "require_monitoring": Param(True, "start only once the observer's `monitoring` is OK, hold on LOST (false: "
                                      "no collision monitoring, e.g. a graph without the observer)"),
    "monitoring_timeout": Param(0.25, "s without a `monitoring` state (the observer re-publishes it every 50 ms) "
                                      "that count as LOST", range=(0.05, 10.0)),
    DESCRIPTION: DESCRIPTION_PARAM}

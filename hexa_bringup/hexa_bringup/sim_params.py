"""The simulator node's parameters (hexa_ros.node.Param): defaults, units, ranges; all read at start-up (read-only)."""
from __future__ import annotations

from hexa.sim.pacing import MAX_LAG, MAX_REAL_TIME_FACTOR
from hexa_bringup.graphs import DEFAULT_REALISM
from hexa_ros.node import Param

PARAMETERS = {
    "scenario": Param("plate", "none | plate | arm | rod | scenario YAML path"),
    "seed": Param(0, "seed of noise and randomized scenarios", range=(0, 2**31 - 1)),
    "randomize": Param(False, "draw the scenario's collision from its ranges with `seed`"),
    "real_time_factor": Param(1.0, "sim s per wall s; 0 = as fast as possible", range=(0.0, MAX_REAL_TIME_FACTOR)),
    "max_lag": Param(MAX_LAG, "wall s behind the pace before the lost time is dropped instead of caught up",
                     range=(0.0, 10.0)),
    "trajectory": Param("", "with scenario none: start at rest at this trajectory's start pose (empty = home)"),
    "camera_rate_hz": Param(30.0, "camera frames per sim s", range=(0.1, 120.0)),
    "cameras": Param(True, "render and publish both RGB-D cameras"),
    "clock_rate_hz": Param(250.0, "/clock messages per sim s", range=(1.0, 10000.0)),
    "truth_rate_hz": Param(100.0, "sim/* ground-truth messages per sim s", range=(0.1, 10000.0)),
    "boards": Param(True, "virtual Uno and Mega on pseudo-terminals at link_dir"),
    "link_dir": Param("/tmp/hexa_sim", "folder of the virtual boards' serial links"),
    "duration": Param(0.0, "sim s to run; 0 = until shut down", range=(0.0, 1e9)),
    "lead_in": Param(0.0, "sim s at rest before the trajectory and the scenario start", range=(0.0, 1e6)),
    "start_delay": Param(0.0, "most wall s with sim time frozen at 0 while the graph starts", range=(0.0, 3600.0)),
    "start_subscribers": Param(0, "with start_delay: the hold ends early once /clock has this many subscribers, "
                                  "each camera an image subscriber and the driver a stream from both boards "
                                  "(0 = hold the whole start_delay)", range=(0, 1000)),
    "contact_model": Param("scripted", "scripted (the scenario's force at the point) | physical (a pushing capsule "
                                       "through MuJoCo contacts)", choices=("scripted", "physical")),
    "servo_frame_period": Param(-1.0, "s between servo set-point frames (0..0.1); < 0 = the description's "
                                      "(or the realism's)", range=(-1.0, 0.1)),
    "realism": Param(DEFAULT_REALISM, "ideal (the robot is the nodes' model) | realistic (a truth drawn from "
                                      "`seed`, servo friction, gear play, dead band, 20 ms pulse frame, ACS712 noise; "
                                      "docs/realism.md)",
                     choices=("ideal", "realistic"))}

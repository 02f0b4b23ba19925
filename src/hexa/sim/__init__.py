"""The simulated Hexa: MuJoCo physics built from the robot description, two RGB-D cameras, scripted
collisions (YAML scenarios), ground truth, and virtual Arduino boards on ptys. See docs/simulator.md.

    from hexa.sim import Simulator, build_mjcf
"""
from __future__ import annotations

from hexa.sim.mjcf import build_mjcf
from hexa.sim.simulator import GroundTruth, SimState, Simulator, SimulatorError

__all__ = ["GroundTruth", "SimState", "Simulator", "SimulatorError", "build_mjcf"]

"""Simulated 3UPS+RPU for the SRM: actuator inner loop, branch-continuous FK pose, optional push by hand.

Model (documented assumptions; seed 003 used a MATLAB/Simulink model it does not describe):
- each actuator is an effective mass m under a PD inner loop tracking q_ind^d,
  m q'' = tau, tau = K_p (q^d - q) - K_d q', K_p = m wn^2, K_d = 2 zeta m wn, speed-limited to v_max;
  integrated with semi-implicit Euler in `substeps` steps per controller sample; tau (N) is the control action;
- the platform pose is the forward kinematics of the actual actuator lengths solved by Newton-Raphson from
  the previous pose, so it stays on the assembly branch continuous with it;
- the "push by hand" is a generalised force F_X on (x_m, z_m, theta, psi) (N, N, N m, N m) resisted by the
  actuators' axial stiffness k_a: the platform deflects by dX = (J_D^T k_a J_D)^-1 F_X, which is small
  away from singularities and large where J_D is near-singular (the paper's uncontrolled motion);
  the encoders (q_c) do not see it, the 3D tracking system (X_c) does.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from hexa.kinematics import upsrpu as kin

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = ["PlantState", "SimulatedUpsrpu", "half_sine_push"]


@dataclass
class PlantState:
    """Measured signals of the simulated robot at one instant."""

    t: float
    q: np.ndarray            # actuator lengths (encoders), m
    q_dot: np.ndarray        # m/s
    tau: np.ndarray          # actuator forces (control actions), N
    X: np.ndarray            # actual platform pose (with the push deflection), as the 3D tracking system sees it
    X_kin: np.ndarray        # pose from FK of q (what a model-based estimate would give)


def half_sine_push(t_start: float, duration: float, force: np.ndarray) -> Callable[[float], np.ndarray]:
    """Generalised force F_X(t): a half-sine pulse of peak `force` (4,) from t_start for `duration` s."""
    force = np.asarray(force, dtype=float)

    def f(t: float) -> np.ndarray:
        if t_start <= t <= t_start + duration:
            return force * np.sin(np.pi * (t - t_start) / duration)
        return np.zeros(4)

    return f


class SimulatedUpsrpu:
    """The 3UPS+RPU under its inner position loop, stepped at the controller sample time."""

    def __init__(self, desc: UpsrpuDescription, X0: np.ndarray, substeps: int = 10,
                 push: Callable[[float], np.ndarray] | None = None, pose_noise: float = 0.0,
                 seed: int = 0, max_deflection: float = 0.05) -> None:
        self.desc = desc
        self.X_kin = np.array(X0, dtype=float)
        self.q = kin.inverse_kinematics(desc, self.X_kin)
        self.q_dot = np.zeros(4)
        self.tau = np.zeros(4)
        self.t = 0.0
        self.substeps = substeps
        self.push = push
        self.pose_noise = pose_noise
        self.rng = np.random.default_rng(seed)
        self.max_deflection = max_deflection
        self.kp = desc.actuator_mass * desc.actuator_wn ** 2
        self.kd = 2.0 * desc.actuator_damping * desc.actuator_mass * desc.actuator_wn
        self.deflection = np.zeros(4)

    def advance(self, q_d: np.ndarray, dt: float) -> PlantState:
        """Track q_d for `dt` s (inner loop), update the pose; return the new measured state."""
        d = self.desc
        h = dt / self.substeps
        q_d = np.asarray(q_d, dtype=float)
        for _ in range(self.substeps):
            self.tau = self.kp * (q_d - self.q) - self.kd * self.q_dot
            self.q_dot = np.clip(self.q_dot + h * self.tau / d.actuator_mass, -d.actuator_v_max, d.actuator_v_max)
            self.q = self.q + h * self.q_dot
        self.t += dt
        self.X_kin = kin.forward_kinematics(d, self.q, self.X_kin)
        self.deflection = self._deflection(self.t)
        return self.state()

    def _deflection(self, t: float) -> np.ndarray:
        if self.push is None:
            return np.zeros(4)
        F = self.push(t)
        if not np.any(F):
            return np.zeros(4)
        J = kin.jacobian_jd(self.desc, self.X_kin)
        K = self.desc.actuator_stiffness * (J.T @ J)
        dX = np.linalg.lstsq(K, F, rcond=None)[0]
        m = float(np.max(np.abs(dX)))
        return dX * (self.max_deflection / m) if m > self.max_deflection else dX

    def state(self) -> PlantState:
        """Current signals; X carries the push deflection and optional tracking noise (std `pose_noise`)."""
        X = self.X_kin + self.deflection
        if self.pose_noise > 0:
            X = X + self.rng.normal(0.0, self.pose_noise, 4)
        return PlantState(self.t, self.q.copy(), self.q_dot.copy(), self.tau.copy(), X, self.X_kin.copy())

"""Hexa dynamics: Lagrange model (seed 000 §2.3), residual observer (§3.1) and Newton–Euler identification (§3.3).

Modules:
- `lagrange`: mass properties from the robot description, inverse dynamics (λ, Q_7..Q_12, plate wrench),
  generalized momentum and the terms of its time derivative (what the momentum observer integrates).
- `observer`: momentum-form residual observer with detection events, and the paper's direct form.
- `identification`: Newton–Euler contact force at a known contact point on the plate, an arm or a rod.
"""
from __future__ import annotations

from hexa.dynamics.identification import ContactForceEstimate, IdentificationError, identify_contact_force
from hexa.dynamics.lagrange import (DynamicsError, HexaDynamicParameters, MotionState, inverse_dynamics,
                                    momentum_terms, motion_from_joint_rates, motion_from_plate)
from hexa.dynamics.observer import (CollisionEvent, ObserverConfig, ObserverError, ResidualObserver, ResidualSample,
                                    direct_residual_batch, momentum_residual_batch)

__all__ = ["CollisionEvent", "ContactForceEstimate", "DynamicsError", "HexaDynamicParameters", "IdentificationError",
           "MotionState", "ObserverConfig", "ObserverError", "ResidualObserver", "ResidualSample",
           "direct_residual_batch", "identify_contact_force", "inverse_dynamics", "momentum_residual_batch",
           "momentum_terms", "motion_from_joint_rates", "motion_from_plate"]

"""`hexa calibrate`: the Hexa's dynamic model, friction, current sensors and servo horns identified from its own motion.

- `excitation`: a periodic Fourier-series excitation per plate DOF, optimized for the regressor's condition number;
- `regressor`: the servo-space dynamic regressor (linear in the plate's and rods' inertial parameters and the
  per-servo inertia, first moment and friction);
- `recording`: the three streams of a run (from a bag or the simulator in-process);
- `identify`: least squares on the regressor (output error, physical bounds, confidence intervals) and the horn
  offsets from the camera poses;
- `overlay`: the calibration overlay every node reads with the robot description, and the per-servo torque model;
- `validate`: the free-motion residual of a held-out run before and after.
See docs/calibration.md.
"""

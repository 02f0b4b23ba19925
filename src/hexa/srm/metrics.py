"""Tracking metrics of the hybrid controller (seed 003 sec 3.1-3.2): MAE, MAPE, MDSR, AVR.

All take arrays (n, F) of the n samples after the enable pin is set (sample k = row 0), SI units in and out.
"""
from __future__ import annotations

import numpy as np

__all__ = ["mae", "mape", "mdsr", "mdsr_as_printed", "avr"]


def _check(*arrays: np.ndarray) -> None:
    shapes = {np.shape(a) for a in arrays}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"metrics need (n, F) arrays of one shape, got {sorted(shapes)}")


def mae(q_ref: np.ndarray, q_meas: np.ndarray) -> float:
    """MAE = 1/F sum_i 1/n sum_j |q^r_ij - q^c_ij| (m)."""
    _check(q_ref, q_meas)
    return float(np.mean(np.mean(np.abs(np.asarray(q_ref) - np.asarray(q_meas)), axis=0)))


def mape(q_ref: np.ndarray, q_meas: np.ndarray) -> float:
    """MAPE = 100/F sum_i 1/n sum_j |(q^r_ij - q^c_ij) / q^r_ij| (%)."""
    _check(q_ref, q_meas)
    q_ref = np.asarray(q_ref, dtype=float)
    return float(100.0 * np.mean(np.mean(np.abs((q_ref - np.asarray(q_meas)) / q_ref), axis=0)))


def mdsr(q_meas: np.ndarray) -> float:
    """Mean distance travelled for the release: 1/F sum_i sum_{j>=2} |q^c_ij - q^c_i(j-1)| (m).

    The printed formula (see `mdsr_as_printed`) is garbled: with the reference constant after activation it
    equals n x MAE, thousands of mm for Table 4's runs, while Table 4 lists 3-35 mm with varying MDSR/MAE
    ratios. This is the quantity the name describes: the path length each actuator travels after k.
    """
    q = np.asarray(q_meas, dtype=float)
    if q.ndim != 2:
        raise ValueError(f"mdsr needs an (n, F) array, got shape {q.shape}")
    return float(np.mean(np.sum(np.abs(np.diff(q, axis=0)), axis=0)))


def mdsr_as_printed(q_ref: np.ndarray, q_meas: np.ndarray) -> float:
    """The formula as printed in seed 003: 1/F sum_i sum_j |q^r_ik - q^c_ij| (m), k = the activation sample."""
    _check(q_ref, q_meas)
    q_ref = np.asarray(q_ref, dtype=float)
    return float(np.mean(np.sum(np.abs(q_ref[0][None, :] - np.asarray(q_meas)), axis=0)))


def avr(tau: np.ndarray) -> float:
    """AVR = 1/F sum_i sum_{j=2}^n |tau_ij - tau_i(j-1)| (N) (seed 003 sec 3.2)."""
    t = np.asarray(tau, dtype=float)
    if t.ndim != 2:
        raise ValueError(f"avr needs an (n, F) array, got shape {t.shape}")
    return float(np.mean(np.sum(np.abs(np.diff(t, axis=0)), axis=0)))

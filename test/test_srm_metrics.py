"""MAE, MAPE, MDSR and AVR (seed 003 sec 3.1-3.2) on hand-checkable series."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.srm import metrics


Q_R = np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]])          # n = 3 samples, F = 2 actuators
Q_C = np.array([[1.0, 2.0], [1.1, 2.0], [1.2, 1.8]])


def test_mae_by_hand():
    # actuator 1: (0 + 0.1 + 0.2) / 3 = 0.1; actuator 2: (0 + 0 + 0.2) / 3 = 0.0667; mean 0.08333
    assert metrics.mae(Q_R, Q_C) == pytest.approx((0.1 + 0.2 / 3) / 2)


def test_mape_by_hand():
    # actuator 1: 100 * 0.1 / 1 = 10 %; actuator 2: 100 * (0.2 / 2) / 3 = 3.333 %; mean 6.667 %
    assert metrics.mape(Q_R, Q_C) == pytest.approx((10.0 + 10.0 / 3) / 2)


def test_mdsr_is_mean_path_length():
    # actuator 1 travels 0.1 + 0.1 = 0.2; actuator 2 travels 0 + 0.2 = 0.2
    assert metrics.mdsr(Q_C) == pytest.approx(0.2)
    back_and_forth = np.array([[0.0], [0.3], [0.0]])
    assert metrics.mdsr(back_and_forth) == pytest.approx(0.6)


def test_mdsr_as_printed_sums_deviation_from_activation_reference():
    # actuator 1: 0 + 0.1 + 0.2 = 0.3; actuator 2: 0 + 0 + 0.2 = 0.2; mean 0.25
    assert metrics.mdsr_as_printed(Q_R, Q_C) == pytest.approx(0.25)


def test_avr_by_hand():
    tau = np.array([[0.0, 1.0], [2.0, 1.0], [1.0, 4.0]])
    # actuator 1: 2 + 1 = 3; actuator 2: 0 + 3 = 3; mean 3
    assert metrics.avr(tau) == pytest.approx(3.0)


def test_shape_mismatch_raises():
    with pytest.raises(ValueError, match="shape"):
        metrics.mae(Q_R, Q_C[:2])

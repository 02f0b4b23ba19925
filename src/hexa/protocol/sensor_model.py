"""Current-sensor and ADC model of the Mega board: ACS712-like Hall sensor into a 10-bit ADC.

    V_out  = V_zero + S * I                      (S: sensitivity, V/A; V_zero: output at 0 A, nominally Vcc/2)
    counts = floor(V_out / V_ref * 2^bits)       clipped to 0 .. 2^bits - 1 (AVR ADC transfer function)
    I      = ((counts + 0.5) * V_ref / 2^bits - V_zero) / S   (mid-step inverse used by the driver)

Defaults: ACS712ELCTR-05B (185 mV/A, +-5 A), V_zero = 2.5 V, V_ref = AVcc = 5.0 V, 10 bits -> 26.4 mA per count.
The driver reads the same parameters from hexa_driver/config/driver.yaml, so board, emulator and driver agree.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np


class SensorModelError(ValueError):
    """Invalid sensor-model parameter (the message names it)."""


@dataclass(frozen=True)
class CurrentSensorModel:
    """ACS712-like sensor + AVR ADC. All SI: volts, amps, V/A."""

    sensitivity: float = 0.185   # V/A
    zero_voltage: float = 2.5    # V at 0 A
    vref: float = 5.0            # V, ADC reference (AVcc)
    bits: int = 10

    def __post_init__(self) -> None:
        if not self.sensitivity > 0:
            raise SensorModelError(f"sensitivity {self.sensitivity} V/A must be > 0")
        if not self.vref > 0:
            raise SensorModelError(f"vref {self.vref} V must be > 0")
        if not 0 <= self.zero_voltage <= self.vref:
            raise SensorModelError(f"zero_voltage {self.zero_voltage} V outside 0..vref={self.vref}")
        if not 1 <= self.bits <= 16:
            raise SensorModelError(f"bits {self.bits} outside 1..16")

    @classmethod
    def from_dict(cls, d: dict) -> "CurrentSensorModel":
        """Model from a config mapping with any of the field names (unknown keys raise SensorModelError)."""
        known = {"sensitivity", "zero_voltage", "vref", "bits"}
        bad = set(d) - known
        if bad:
            raise SensorModelError(f"unknown sensor-model key(s) {sorted(bad)}; known: {sorted(known)}")
        values: dict[str, Any] = {k: (int(v) if k == "bits" else float(v)) for k, v in d.items()}
        return cls(**values)

    @property
    def full_scale(self) -> int:
        """Number of ADC steps, 2^bits (1024 for 10 bits)."""
        return 1 << self.bits

    @property
    def amps_per_count(self) -> float:
        """Current resolution of one ADC step (A)."""
        return self.vref / self.full_scale / self.sensitivity

    def voltage_from_current(self, amps: float | np.ndarray) -> float | np.ndarray:
        """Sensor output voltage (V) for a current (A)."""
        if isinstance(amps, np.ndarray):
            return self.zero_voltage + self.sensitivity * amps.astype(float)
        return self.zero_voltage + self.sensitivity * float(amps)

    def counts_from_voltage(self, volts: float | Sequence[float] | np.ndarray) -> np.ndarray:
        """ADC counts for input voltages (AVR transfer function, clipped to the ADC range); int array."""
        v = np.asarray(volts, dtype=float)
        c = np.floor(v / self.vref * self.full_scale)
        return np.clip(c, 0, self.full_scale - 1).astype(np.int64)

    def counts_from_current(self, amps: float | Sequence[float] | np.ndarray) -> np.ndarray:
        """ADC counts for currents (A); int array of the same shape."""
        a = np.asarray(amps, dtype=float)
        return self.counts_from_voltage(self.zero_voltage + self.sensitivity * a)

    def current_from_counts(self, counts: int | Sequence[int] | np.ndarray) -> np.ndarray:
        """Currents (A) for ADC counts, at the middle of each ADC step; float array."""
        c = np.asarray(counts, dtype=float)
        return ((c + 0.5) * self.vref / self.full_scale - self.zero_voltage) / self.sensitivity

    def voltage_from_counts(self, counts: int | Sequence[int] | np.ndarray) -> np.ndarray:
        """Mid-step input voltage (V) for ADC counts."""
        return (np.asarray(counts, dtype=float) + 0.5) * self.vref / self.full_scale


DEFAULT_SENSOR = CurrentSensorModel()

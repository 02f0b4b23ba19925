"""The cached calibration of a simulated robot (hexa.calibration.simulated.simulated_calibration): identified once
per robot (seed, realism, description, code), then read from the cache; the demo's and sim mode's nodes get it on the
realistic robot and nothing on the ideal one. The identification itself is tested in test_calibration.py; here it
is replaced by a recorder of its calls."""
from __future__ import annotations

from pathlib import Path

import pytest

from hexa.calibration import simulated
from hexa.sim.realism import RealismConfig


@pytest.fixture
def calls(monkeypatch) -> list:
    """Design and identification stand-ins that record their calls and write small files."""
    import hexa.calibration.excitation as excitation

    seen: list = []

    class _Design:
        def write(self, path, rate_hz):
            Path(path).write_text("# design\n0 0 0 0 0 0 0\n")
            return Path(path)

    def design(desc, settings):
        seen.append(("design",))
        return _Design()

    def calibrate(exc, seed, realism, desc, out):
        assert Path(exc).read_text().startswith("# design")      # the cached excitation file is what it plays
        seen.append(("identify", seed, realism.name))
        Path(out).write_text(f"calibration_of: ''\ncalibration: {{seed: {seed}}}\n")
        return None, None

    monkeypatch.setattr(excitation, "design_excitation", design)
    monkeypatch.setattr(simulated, "calibrate_simulated_robot", calibrate)
    return seen


def test_a_simulated_robot_is_calibrated_once_and_each_robot_has_its_own_overlay(tmp_path, calls):
    real = RealismConfig.realistic()
    a = simulated.simulated_calibration(0, real, cache=tmp_path)
    assert a.is_file() and "seed: 0" in a.read_text()
    assert calls == [("design",), ("identify", 0, "realistic")]
    assert simulated.simulated_calibration(0, real, cache=tmp_path) == a        # the cache: nothing redone
    assert len(calls) == 2
    b = simulated.simulated_calibration(3, real, cache=tmp_path)                # another truth: its own overlay
    assert b != a and "seed: 3" in b.read_text() and calls[2:] == [("identify", 3, "realistic")]
    other = real.replace(tolerances=real.tolerances.__class__(mass=0.1))        # another truth draw
    c = simulated.simulated_calibration(0, other, cache=tmp_path)
    assert c not in (a, b) and calls[3:] == [("identify", 0, "realistic")]   # the excitation is reused
    desc = tmp_path / "own.yaml"                                                 # another description: all anew
    desc.write_text((simulated.Path(simulated.__file__).parents[1] / "robots" / "hexa.yaml").read_text() + "\n")
    d = simulated.simulated_calibration(0, real, description=desc, cache=tmp_path)
    assert d not in (a, b, c) and calls[4:] == [("design",), ("identify", 0, "realistic")]
    assert not list(tmp_path.glob("*.tmp*"))                                     # written whole, then renamed


def test_the_nodes_run_the_calibration_on_the_realistic_robot_and_the_model_on_the_ideal_one(tmp_path, calls,
                                                                                          monkeypatch):
    from hexa_bringup.demo_run import nodes_description

    monkeypatch.setenv("HEXA_CACHE_DIR", str(tmp_path))
    assert nodes_description("ideal", 0) is None and calls == []
    p = nodes_description("realistic", 5)
    assert p is not None and p.parent == tmp_path / "calibration" and calls[-1] == ("identify", 5, "realistic")
    with pytest.raises(ValueError, match="realism"):
        nodes_description("kind", 0)

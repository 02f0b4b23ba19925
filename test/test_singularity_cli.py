"""`hexa singularity` prints det J_D and the six Omega_ij of the 3UPS+RPU (JSON, SI units + degrees)."""
from __future__ import annotations

import json

import pytest

from hexa_bringup.cli import main


def test_singularity_json_at_table3_pose_one(capsys):
    assert main(["singularity", "--robot", "upsrpu", "--pose", "0.01", "0.70", "0.15", "0.31", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["omega_deg"]) == {"1-2", "1-3", "1-4", "2-3", "2-4", "3-4"}
    assert out["min_pair"] == "3-4"
    assert out["min_omega_deg"] == pytest.approx(min(out["omega_deg"].values()))
    assert out["min_omega_deg"] < 1.8 and out["near"] is True
    assert abs(out["det_jd"]) < 0.015


def test_singularity_non_singular_pose_is_not_near(capsys):
    assert main(["singularity", "--robot", "upsrpu", "--pose", "0", "0.7", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["near"] is False and out["det_jd"] > 0.015


def test_singularity_rejects_a_pose_of_the_wrong_length(capsys):
    assert main(["singularity", "--robot", "upsrpu", "--pose", "0", "0.7", "0"]) == 2     # a user error: exit 2
    err = capsys.readouterr().err
    assert "x_m z_m theta psi" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1

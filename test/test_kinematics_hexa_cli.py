"""The `hexa robot show`, `hexa ik` and `hexa fk` commands (JSON, SI units, exit status)."""
from __future__ import annotations

import json

import numpy as np

from hexa_bringup.cli import main


def _json(capsys, argv):
    rc = main(argv)
    return rc, json.loads(capsys.readouterr().out)


def test_robot_show_hexa_json_has_geometry(capsys):
    rc, d = _json(capsys, ["robot", "show", "hexa", "--json"])
    assert rc == 0 and d["l_a"] == 0.2 and len(d["A"]) == 6 and d["home_pose"][2] == -0.55


def test_robot_show_upsrpu_json(capsys):
    rc, d = _json(capsys, ["robot", "show", "upsrpu", "--json"])
    assert rc == 0 and d["kind"] == "upsrpu" and len(d["singular_poses"]) == 5


def test_ik_then_fk_round_trip_through_the_cli(capsys):
    pose = [0.03, -0.02, -0.54, 0.05, 0.2, -0.1]
    rc, ik = _json(capsys, ["ik", "--robot", "hexa", "--pose", *map(str, pose), "--json"])
    assert rc == 0 and len(ik["joints"]) == 6
    rc, fk = _json(capsys, ["fk", "--robot", "hexa", "--joints", *map(repr, ik["joints"]), "--json"])
    assert rc == 0 and fk["method"] == "newton-raphson"
    got = [fk["pose"][k] for k in ("x", "y", "z", "alpha", "beta", "gamma")]
    assert np.allclose(got, pose, atol=1e-9)


def test_ik_unreachable_pose_exits_2_naming_the_chain(capsys):
    rc, err = _json(capsys, ["ik", "--robot", "hexa", "--pose", "0", "0", "-0.95", "0", "0", "0", "--json"])
    assert rc == 2 and "chain" in err["error"] and 1 <= err["chain"] <= 6


def test_upsrpu_ik_and_fk(capsys):
    rc, ik = _json(capsys, ["ik", "--robot", "upsrpu", "--pose", "0.02", "0.7", "0.05", "-0.03", "--json"])
    assert rc == 0 and len(ik["joints"]) == 4
    rc, fk = _json(capsys, ["fk", "--robot", "upsrpu", "--joints", *map(repr, ik["joints"]), "--json"])
    got = [fk["pose"][k] for k in ("x_m", "z_m", "theta", "psi")]
    assert rc == 0 and np.allclose(got, [0.02, 0.7, 0.05, -0.03], atol=1e-9)


def test_wrong_pose_length_is_an_error(capsys):
    assert main(["ik", "--robot", "hexa", "--pose", "0", "0", "-0.5"]) == 2                 # a user error: exit 2
    err = capsys.readouterr().err
    assert err.startswith("hexa ik") and len(err.strip().splitlines()) == 1


def test_fk_ann_is_close_to_newton_raphson(capsys):
    pose = [0.05, 0.0, -0.55, 0.0, 0.1, 0.0]
    rc, ik = _json(capsys, ["ik", "--robot", "hexa", "--pose", *map(str, pose), "--json"])
    rc, fk = _json(capsys, ["fk", "--robot", "hexa", "--ann", "--joints", *map(repr, ik["joints"]), "--json"])
    assert rc == 0 and fk["method"] == "ann"
    got = np.array([fk["pose"][k] for k in ("x", "y", "z", "alpha", "beta", "gamma")])
    assert np.max(np.abs(got[:3] - pose[:3])) < 0.002 and np.max(np.abs(got[3:] - pose[3:])) < np.radians(0.5)

"""hexa in a colcon workspace: the ament_python packages declare what they import, form no dependency cycle, build
with colcon into a fresh install space over the venv's ROS (the underlay), install their executables where
`ros2 run` looks (lib/<package>), and a user's own package that imports hexa_msgs builds and runs beside them."""
from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

# colcon builds: left out of `make check`; ROS processes that need no timing: on two workers in `make test`
pytestmark = [pytest.mark.slow, pytest.mark.ros_parallel]

REPO = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
PACKAGES = {"hexa_ros": REPO / "src" / "hexa_ros", "hexa_bringup": REPO / "hexa_bringup",
            "hexa_driver": REPO / "hexa_driver", "hexa_dynamics": REPO / "hexa_dynamics",
            "hexa_vision": REPO / "hexa_vision"}
#: Python modules that are not ROS packages, by the rosdep key a package.xml names for them
PYTHON_KEYS = {"numpy": "python3-numpy", "yaml": "python3-yaml", "cv2": "python3-opencv", "serial": "python3-serial",
               "scipy": "python3-scipy", "argcomplete": "python3-argcomplete"}
#: modules a package imports that no package.xml can name: the ROS-free core (pip-installed) and its pip-only deps
NOT_ROS = {"hexa", "rosbags", "setuptools", "foxglove", "pyrealsense2"}

USER_PKG_SETUP = '''from setuptools import setup
setup(name="my_listener", version="0.0.1", packages=["my_listener"],
      data_files=[("share/ament_index/resource_index/packages", ["resource/my_listener"]),
                  ("share/my_listener", ["package.xml"])],
      entry_points={"console_scripts": ["listener = my_listener.main:main"]})
'''
USER_PKG_XML = '''<?xml version="1.0"?>
<package format="3">
  <name>my_listener</name><version>0.0.1</version><description>a user's node on hexa_msgs</description>
  <maintainer email="u@example.invalid">user</maintainer><license>Apache-2.0</license>
  <exec_depend>rclpy</exec_depend><exec_depend>hexa_msgs</exec_depend>
  <export><build_type>ament_python</build_type></export>
</package>
'''
USER_PKG_MAIN = '''import sys
from hexa_msgs.msg import CollisionEvent
from rclpy.serialization import deserialize_message, serialize_message


def main():
    m = CollisionEvent(axis_name="fz", peak=12.5)
    back = deserialize_message(serialize_message(m), CollisionEvent)
    print(type(back).__module__, back.axis_name, back.peak, sys.modules["hexa_msgs"].__file__)
    return 0
'''


def _stdlib() -> set[str]:
    return set(sys.stdlib_module_names) | {"__future__"}


def _imports(pkg_dir: Path) -> set[str]:
    """Top-level module names imported anywhere in a package's sources (also inside functions)."""
    names: set[str] = set()
    for f in pkg_dir.rglob("*.py"):
        if "test" in f.relative_to(pkg_dir).parts or f.name == "setup.py":
            continue
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
    return names


def _exec_depends(pkg_dir: Path) -> set[str]:
    from catkin_pkg.package import parse_package

    p = parse_package(str(pkg_dir / "package.xml"))
    return {d.name for d in p.exec_depends + p.run_depends + p.build_export_depends}


def test_each_package_xml_names_every_ros_and_python_dependency_it_imports():
    missing = {}
    for name, path in PACKAGES.items():
        declared = _exec_depends(path)
        needed = set()
        for mod in _imports(path) - _stdlib() - NOT_ROS - {name}:
            needed.add(PYTHON_KEYS.get(mod, mod))
        if needed - declared:
            missing[name] = sorted(needed - declared)
    assert not missing, f"package.xml lacks exec_depend for imported modules: {missing}"


def test_hexa_packages_form_no_dependency_cycle():
    graph = {n: _exec_depends(p) & set(PACKAGES) for n, p in PACKAGES.items()}
    assert "hexa_bringup" not in set().union(*(graph[n] for n in graph if n != "hexa_bringup")), graph
    done: set[str] = set()

    def visit(n: str, stack: tuple[str, ...]) -> None:
        assert n not in stack, f"dependency cycle: {' -> '.join(stack + (n,))}"
        if n not in done:
            for d in graph[n]:
                visit(d, stack + (n,))
            done.add(n)

    for n in graph:
        visit(n, ())


def _workspace_env(install: Path, ros_env: dict[str, str]) -> dict[str, str]:
    """The environment after `. install/setup.sh` (colcon's own script), on top of the test's ROS environment."""
    out = subprocess.run(["sh", "-c", f". '{install}/setup.sh' && env -0"], env=ros_env, capture_output=True,
                         check=True, timeout=60).stdout.decode()
    return dict(kv.split("=", 1) for kv in out.split("\0") if "=" in kv)


def test_colcon_builds_the_repository_and_a_user_package_and_the_installed_node_runs(tmp_path, ros_env, procs):
    user = tmp_path / "src" / "my_listener"
    (user / "my_listener").mkdir(parents=True)
    (user / "resource").mkdir()
    (user / "resource" / "my_listener").write_text("")
    (user / "my_listener" / "__init__.py").write_text("")
    (user / "my_listener" / "main.py").write_text(USER_PKG_MAIN)
    (user / "setup.py").write_text(USER_PKG_SETUP)
    (user / "setup.cfg").write_text("[develop]\nscript_dir=$base/lib/my_listener\n"
                                    "[install]\ninstall_scripts=$base/lib/my_listener\n")
    (user / "package.xml").write_text(USER_PKG_XML)
    env = dict(ros_env, AMENT_PREFIX_PATH=str(VENV), CMAKE_PREFIX_PATH=str(VENV),
               PATH=f"{VENV / 'bin'}:{os.environ['PATH']}")
    install = tmp_path / "install"
    t0 = time.monotonic()
    r = subprocess.run([str(VENV / "bin" / "colcon"), "--log-base", str(tmp_path / "log"), "build",
                        "--base-paths", *map(str, PACKAGES.values()), str(user),
                        "--build-base", str(tmp_path / "build"), "--install-base", str(install),
                        "--event-handlers", "console_cohesion-", "summary-"],
                       env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    print(f"colcon build: {time.monotonic() - t0:.1f} s")
    for pkg, exes in {"hexa_bringup": ["hexa", "hexa-sim", "hexa-view"], "hexa_driver": ["hexa-driver"],
                      "hexa_dynamics": ["hexa-observer", "hexa-rnea", "hexa-singularity", "hexa-trajectory"],
                      "hexa_vision": ["hexa-camera", "hexa-vision-pose", "hexa-vision-isolation"],
                      "my_listener": ["listener"]}.items():
        for exe in exes:
            assert os.access(install / pkg / "lib" / pkg / exe, os.X_OK), f"{pkg}/lib/{pkg}/{exe} not installed"
    assert (install / "hexa_ros" / "lib" / "python3.11" / "site-packages" / "hexa_ros" / "config"
            / "fastdds_profile.xml").is_file()
    wenv = _workspace_env(install, env)

    # the user's package runs from the install space and finds hexa_msgs in the underlay
    u = subprocess.run([str(install / "my_listener" / "lib" / "my_listener" / "listener")], env=wenv,
                       capture_output=True, text=True, timeout=60)
    assert u.returncode == 0, u.stderr
    assert u.stdout.split()[:3] == ["hexa_msgs.msg._collision_event", "fz", "12.5"], u.stdout

    # the installed modules, not the venv's editable sources, are what the workspace imports
    where = subprocess.run([sys.executable, "-c", "import hexa_dynamics, hexa_ros; print(hexa_dynamics.__file__);"
                            "print(hexa_ros.__file__)"], env=wenv, capture_output=True, text=True, timeout=60)
    assert all(line.startswith(str(install)) for line in where.stdout.split()), where.stdout + where.stderr

    # a node started from install/<pkg>/lib/<pkg>/ joins the graph: the installed `hexa` CLI reads its parameter
    node = procs.start([str(install / "hexa_dynamics" / "lib" / "hexa_dynamics" / "hexa-singularity"),
                        "--ros-args", "-r", "__ns:=/ws", "-p", "omega_limit:=0.125"], wenv)
    got = ""
    deadline = time.monotonic() + 45
    while time.monotonic() < deadline and "0.125" not in got:
        q = subprocess.run([str(install / "hexa_bringup" / "lib" / "hexa_bringup" / "hexa"), "param", "get",
                            "/ws/singularity", "omega_limit"], env=wenv, capture_output=True, text=True, timeout=60)
        got = q.stdout
        if "0.125" not in got:
            time.sleep(0.5)
    assert "0.125" in got, (got, node.poll())
    node.send_signal(signal.SIGINT)
    _out, err = node.communicate(timeout=20)
    assert node.returncode == 0 and "Traceback" not in err, err


def _python312() -> str | None:
    import shutil

    for cand in (shutil.which("python3.12"), *sorted(Path("/root/.pyenv/versions").glob("3.12*/bin/python3.12"))):
        if cand and subprocess.run([str(cand), "--version"], capture_output=True).returncode == 0:
            return str(cand)
    return None


def test_the_sources_compile_on_python_3_12():
    """Ubuntu 24.04's apt Jazzy runs Python 3.12: nothing in hexa may need 3.11-only syntax or removed modules."""
    py = _python312()
    if py is None:
        pytest.skip("no Python 3.12 interpreter on this machine")
    roots = [REPO / "src" / "hexa", *PACKAGES.values()]
    code = ("import pathlib, sys\n"
            "bad = []\n"
            "for root in sys.argv[1:]:\n"
            "    for f in pathlib.Path(root).rglob('*.py'):\n"
            "        try:\n"
            "            compile(f.read_text(), str(f), 'exec')\n"
            "        except SyntaxError as e:\n"
            "            bad.append(f'{f}: {e}')\n"
            "print('\\n'.join(bad)); sys.exit(1 if bad else 0)\n")
    r = subprocess.run([py, "-c", code, *map(str, roots)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    removed = {"distutils", "imp", "asynchat", "asyncore", "smtpd"}
    for root in roots:
        used = _imports(root) & removed
        assert not used, f"{root} imports modules removed in Python 3.12: {used}"


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))

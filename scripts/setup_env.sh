#!/usr/bin/env bash
# One idempotent set-up for `make test` and `make demo`: venv, pinned wheels, CMake export repair, hexa_msgs and
# tf2_msgs builds (kept in a build cache under ~/.cache/hexa-build), hexa Python packages, AVR toolchain. Each step is
# skipped when its inputs have not changed (stamps in .venv/.stamps).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
STAMPS="$VENV/.stamps"
PY=${PYTHON:-python3.11}
t0=$(date +%s)

log() { printf '[setup %3ss] %s\n' "$(( $(date +%s) - t0 ))" "$*"; }
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }
# done_or_mark NAME HASH: returns 0 (skip) when the stamp matches
fresh() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
mark() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

# 1. Debian packages: AVR toolchain and simavr for the firmware and its firmware-in-the-loop tests; EGL for MuJoCo
#    headless rendering; iproute2 for the
#    two-host test. Installed once (dpkg knows).
APT_PKGS=(gcc-avr avr-libc arduino-core-avr arduino-mk simavr libsimavr-dev libelf-dev pkg-config iproute2 make cmake g++
          libegl1 libegl-mesa0 libgl1-mesa-dri)
missing=()
for p in "${APT_PKGS[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    log "apt-get install ${missing[*]}"
    apt-get update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "setup: missing Debian packages ${missing[*]}; run: sudo apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
fi

# 2. The venv (CPython 3.11).
if [ ! -x "$VENV/bin/python" ]; then
  log "creating $VENV with $PY"
  "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
  || { echo "setup: .venv must be CPython 3.11; remove .venv and install python3.11" >&2; exit 1; }
# --no-compile: Python compiles a module on its first import (pip would byte-compile every file of every wheel, ≈ 25 s)
PIP=("$VENV/bin/python" -m pip install --disable-pip-version-check -q --no-compile)

# 3. Pinned wheels: core, ROS 2 Jazzy runtime, build-only ROS packages. torch is the local CPU build (never unpinned).
#    uv (requirements/uv.txt, installed by pip) installs them: it links the wheels from its cache, so a fresh clone
#    takes seconds instead of pip's ≈ 40 s of unpacking. It reads no pip configuration, so the machine's pip
#    find-links (PIP_FIND_LINKS or pip.conf: where the local torch wheel is) and index are passed on. pip installs
#    them when uv is unavailable or fails.
UV="$VENV/bin/uv"
uv_pinned=$(sed -n 's/^uv==//p' requirements/uv.txt)
if [ ! -x "$UV" ] || [ "$("$UV" --version 2>/dev/null | cut -d' ' -f2)" != "$uv_pinned" ]; then
  mkdir -p build
  "${PIP[@]}" -r requirements/uv.txt > build/pip-uv.log 2>&1 \
    || { rm -f "$UV"; log "pip could not install uv (build/pip-uv.log): pip installs the wheels"; }
fi
UV_ARGS=()   # pip's find-links and index for uv, read once, on the first install
uv_install() {
  [ -x "$UV" ] || return 1
  if [ ${#UV_ARGS[@]} -eq 0 ]; then
    local links idx
    UV_ARGS=(pip install --python "$VENV/bin/python" -q)
    links=${PIP_FIND_LINKS:-$("$VENV/bin/python" -m pip config get global.find-links 2>/dev/null || true)}
    for l in $links; do UV_ARGS+=(--find-links "$l"); done
    idx=${PIP_INDEX_URL:-$("$VENV/bin/python" -m pip config get global.index-url 2>/dev/null || true)}
    [ -z "$idx" ] || UV_ARGS+=(--index-url "$idx")
  fi
  "$UV" "${UV_ARGS[@]}" "$@"
}
WHEEL_REQS=(-r requirements/core.txt -r requirements/torch.txt -r requirements/ros.txt -r requirements/ros-build.txt)
h=$(hash_of requirements/*.txt)
if ! fresh wheels "$h"; then
  log "installing pinned wheels (requirements/*.txt)"
  uv_install "${WHEEL_REQS[@]}" || { log "uv unavailable or failed: installing with pip"; "${PIP[@]}" "${WHEEL_REQS[@]}" \
    2> >(grep -v "is ignored: it is neither" >&2); }
  mark wheels "$h"
  rm -f "$STAMPS/cmake-fix" "$STAMPS/msgs"
fi

# 4. Repair the wheels' CMake exports, which point at their build container's /opt/python/cp311-cp311.
PYINC=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
NPINC=$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')
if ! fresh cmake-fix "$PYINC:$NPINC"; then
  log "repairing CMake exports under .venv/share"
  { grep -rlF "/opt/python/cp311-cp311" "$VENV/share" --include="*.cmake" || true; } | while read -r f; do
    sed -i -e "s#/opt/python/cp311-cp311/include/python3.11#$PYINC#g" \
           -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NPINC#g" \
           -e "s#/opt/python/cp311-cp311#$VENV#g" "$f"
  done
  mark cmake-fix "$PYINC:$NPINC"
fi

# 5. The interface packages with colcon (settings in colcon.meta), installed into the venv prefix (no runtime env vars
#    needed): hexa_msgs, and tf2_msgs (third_party/tf2_msgs, ROS 2 Jazzy's source: no tf2_msgs wheel exists) so that
#    /tf and /tf_static carry the standard tf2_msgs/msg/TFMessage type.
MSG_PKGS=(hexa_msgs third_party/tf2_msgs)
h=$(for p in "${MSG_PKGS[@]}"; do cat "$p/CMakeLists.txt" "$p/package.xml" "$p"/msg/* "$p"/srv/* "$p"/action/* \
      2>/dev/null; done | cat - colcon.meta | sha256sum | cut -c1-16)
#    The built files are kept in a build cache outside the checkout (like mypy's), keyed by those sources, the pinned
#    wheels and the Python: a fresh clone with the same inputs restores them instead of compiling again (≈ 1–2 min).
#    HEXA_BUILD_CACHE="" turns the cache off; removing the directory forces a build.
CACHE_DIR=${HEXA_BUILD_CACHE-$HOME/.cache/hexa-build}
CACHE_TAR=""
if [ -n "$CACHE_DIR" ]; then
  CACHE_TAR="$CACHE_DIR/msgs-$(printf '%s' "$h" "$(hash_of requirements/*.txt)" "$("$VENV/bin/python" -VV)" \
    | sha256sum | cut -c1-16).tar"
fi
importable() { "$VENV/bin/python" -c 'import hexa_msgs.msg, tf2_msgs.msg, hexa_msgs.srv' 2>/dev/null; }
if ! fresh msgs "$h" || ! importable; then
  restored=0
  if [ -n "$CACHE_TAR" ] && [ -f "$CACHE_TAR" ]; then
    log "restoring ${MSG_PKGS[*]} from the build cache ($CACHE_TAR)"
    if tar -xf "$CACHE_TAR" -C "$VENV" 2>/dev/null && old=$(cat "$VENV/.msgs-build-prefix" 2>/dev/null); then
      # the few text files that name the prefix they were built for (CMake exports, setup scripts)
      if [ "$old" != "$VENV" ]; then
        tar -tf "$CACHE_TAR" | while read -r f; do
          if [ -f "$VENV/$f" ] && grep -qIF "$old" "$VENV/$f" 2>/dev/null; then sed -i "s#$old#$VENV#g" "$VENV/$f"; fi
        done
      fi
      importable && restored=1
    fi
    rm -f "$VENV/.msgs-build-prefix"
    [ $restored = 1 ] || log "the cached build does not import here: building"
  fi
  if [ $restored = 0 ]; then
    log "building ${MSG_PKGS[*]} (colcon)"
    mkdir -p build
    (
      export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH"
      export PYTHONPATH="$VENV/lib/python3.11/site-packages"
      "$VENV/bin/colcon" --log-base build/log build --base-paths "${MSG_PKGS[@]}" --build-base build/colcon \
        --install-base "$VENV" --merge-install --metas colcon.meta --event-handlers console_cohesion- summary- \
        > build/colcon-msgs.log 2>&1 || { tail -40 build/colcon-msgs.log >&2; exit 1; }
    )
    importable || { echo "setup: hexa_msgs/tf2_msgs built but not importable" >&2; exit 1; }
    if [ -n "$CACHE_TAR" ]; then
      # every installed file (colcon's install manifests), relative to the venv, and the prefix they were built for
      mkdir -p "$CACHE_DIR" && echo "$VENV" > "$VENV/.msgs-build-prefix"
      { echo .msgs-build-prefix; for p in "${MSG_PKGS[@]}"; do   # (a manifest's last line has no newline)
          { cat "build/colcon/$(basename "$p")/install_manifest.txt"; echo; } | sed -n "s#^$VENV/##p"; done
      } > build/msgs-files.txt
      tar -cf "$CACHE_TAR.tmp.$$" -C "$VENV" -T build/msgs-files.txt 2>/dev/null \
        && mv "$CACHE_TAR.tmp.$$" "$CACHE_TAR" || rm -f "$CACHE_TAR.tmp.$$"
      rm -f "$VENV/.msgs-build-prefix"
    fi
  fi
  mark msgs "$h"
fi

# 6. Our Python packages (editable): the ROS-free core and the ROS packages' nodes and entry points.
PKGS=(. src/hexa_ros hexa_bringup hexa_dynamics hexa_vision hexa_driver)
h=$(for p in "${PKGS[@]}"; do cat "$p/setup.py" "$p/pyproject.toml" 2>/dev/null || true; done | sha256sum | cut -c1-16)
if ! fresh pkgs "$h"; then
  log "installing hexa packages (editable)"
  editable=()
  for p in "${PKGS[@]}"; do
    if [ -f "$p/setup.py" ] || [ -f "$p/pyproject.toml" ]; then editable+=(-e "$p"); fi
  done
  mkdir -p build
  if ! uv_install --no-deps --no-build-isolation "${editable[@]}" > build/pip-editable.log 2>&1; then
    "${PIP[@]}" --no-deps --no-build-isolation "${editable[@]}" > build/pip-editable.log 2>&1 \
      || { cat build/pip-editable.log >&2; exit 1; }
  fi
  mark pkgs "$h"
fi
log "environment ready ($VENV)"

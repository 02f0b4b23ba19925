#!/usr/bin/env bash
# The test suite as `make test` runs it, in two parts: first, on two workers (pytest-xdist, one module per worker at a
# time), the tests that start no ROS processes and the `ros_parallel` ones (ROS processes whose graph only has to
# answer: CLI verbs, bags, README commands); then the other `ros` tests (test/conftest.py) one at a time, since they
# measure a live graph that must not share the two cores with other tests. Both parts always run; the exit
# status is the first failure's. pytest's "no tests collected" (5) counts as a failure unless extra arguments
# (PYTEST_ARGS, e.g. -k) select tests of the other part only.
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
common=(-q -p no:cacheprovider "$@")
# The simulated robot's default is the realistic one, whose nodes run a calibration overlay identified on it (≈ 25 s
# of CPU the first time, then cached per robot): identify seed 0's once here, so that no test's graph waits for it.
"$PY" -c 'from hexa_bringup.demo_run import nodes_description as d; from hexa_bringup.graphs import DEFAULT_REALISM as r
d(r, 0, log=lambda line: print(f"make test: {line}", flush=True))' || { echo "make test: calibrating the simulated robot failed" >&2; exit 1; }
"$PY" -m pytest test/ -m "not ros or ros_parallel" -n 2 --dist loadfile --durations=5 "${common[@]}"
rc1=$?
"$PY" -m pytest test/ -m "ros and not ros_parallel" --durations=15 "${common[@]}"
rc2=$?
if [ $rc1 -eq 5 ] && [ $rc2 -eq 5 ]; then echo "make test: pytest collected no tests" >&2; exit 1; fi
if [ $# -eq 0 ] && { [ $rc1 -eq 5 ] || [ $rc2 -eq 5 ]; }; then
  echo "make test: a part of the suite collected no tests" >&2; exit 1
fi
for rc in $rc1 $rc2; do
  if [ $rc -ne 0 ] && [ $rc -ne 5 ]; then exit $rc; fi
done
exit 0

#!/usr/bin/env bash
# The test suite: sets itself up like run_local.sh, then runs pytest (docs/testing.md).
#   deploy/run_tests.sh               the whole suite in three parts, each test's name and result as it ends:
#                                     1. the unit tests, then the system tests marked `parallel`, on every CPU
#                                        (pytest-xdist; RECONSWARM_TEST_WORKERS=N for N workers, 0 for none);
#                                     2. the other system tests (lockstep launches), two at a time (one test
#                                        module per worker; one at a time on one CPU or with WORKERS=0);
#                                     3. those marked `realtime`, one at a time, with nothing else of the suite.
#                                     Then the 20 slowest tests of the whole run. A failing part does not stop the
#                                     next; Ctrl-C stops the run after pytest's summary of what ran.
#   deploy/run_tests.sh ARGS...       one pytest run with ARGS: deploy/run_tests.sh tests/unit, -m "not realtime", -k x
#   --ports A-B (or RECONSWARM_TEST_PORTS=A-B)   the ports the tests choose come from A..B (1024 <= A <= B <= 65535),
#                                     shared out among the workers of part 1
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup_env.sh"
cd "$root"

args=()
while (($#)); do
    case "$1" in
        --ports) [ $# -ge 2 ] || { echo "run_tests.sh: error: --ports: expected A-B" >&2; exit 2; }
                 export RECONSWARM_TEST_PORTS="$2"; shift 2 ;;
        --ports=*) export RECONSWARM_TEST_PORTS="${1#--ports=}"; shift ;;
        *) args+=("$1"); shift ;;
    esac
done
if [ -n "${RECONSWARM_TEST_PORTS:-}" ]; then
    if ! [[ "$RECONSWARM_TEST_PORTS" =~ ^([0-9]{4,5})-([0-9]{4,5})$ ]] || ((10#${BASH_REMATCH[1]} < 1024 ||
            10#${BASH_REMATCH[1]} > 10#${BASH_REMATCH[2]} || 10#${BASH_REMATCH[2]} > 65535)); then
        echo "run_tests.sh: error: --ports / RECONSWARM_TEST_PORTS: expected A-B with 1024 <= A <= B <= 65535," \
             "got '$RECONSWARM_TEST_PORTS'" >&2
        exit 2
    fi
fi

pytest=("$venv/bin/python" -m pytest)
if ((${#args[@]})); then
    exec "${pytest[@]}" --durations=20 "${args[@]}"  # (the slowest 20: what the time goes to)
fi

workers="${RECONSWARM_TEST_WORKERS:-auto}"
if [ "$workers" != 0 ] && ! "$venv/bin/python" -c "import xdist" 2>/dev/null; then
    echo "run_tests.sh: pytest-xdist is not installed: part 1 runs in this process" >&2
    workers=0
fi
parallel=()
[ "$workers" = 0 ] || parallel=(-n "$workers")
reports="$(mktemp -d)"
trap 'rm -rf "$reports"' EXIT
failed=()

part() {  # part NAME PYTEST-ARGS...: run one part; stop the script if pytest was interrupted or could not run
    local name="$1" rc=0
    shift
    echo
    echo "======== run_tests.sh: part $name ========"
    "${pytest[@]}" --durations=10 --junitxml="$reports/$name.xml" "$@" || rc=$?
    case "$rc" in
        0|5) ;;                      # passed, or nothing selected
        1) failed+=("$name") ;;      # tests failed: the next parts still run
        *) echo "run_tests.sh: part $name ended with pytest's exit code $rc (2: interrupted): stopping" >&2
           exit "$rc" ;;
    esac
}

part 1-unit-and-parallel "${parallel[@]}" -m "not system or parallel" tests/unit tests/system
# Part 2 on two workers: a lockstep launch leaves part of 2 CPUs idle while it waits for messages (85 tests: 818 s
# on two workers, 982 s one at a time, the same idle 2-CPU machine); a module's tests stay on one worker (its shared
# launch runs once).
pair=()
[ "$workers" = 0 ] || [ "$(nproc)" -lt 2 ] || pair=(-n 2 --dist loadscope)
part 2-system -v "${pair[@]}" -m "system and not parallel and not realtime" tests/system
part 3-realtime -v -m "system and realtime" tests/system

"$venv/bin/python" - "$reports"/*.xml <<'EOF'
import sys
import xml.etree.ElementTree as ET

rows, parts = [], []
for path in sys.argv[1:]:
    suite = ET.parse(path).getroot().find("testsuite")
    if suite is None:
        continue
    parts.append(f"{path.rsplit('/', 1)[1][:-4]}: {suite.get('tests')} tests in {float(suite.get('time', 0)):.0f} s")
    rows += [(float(c.get("time", 0)), f"{c.get('classname', '').replace('.', '/')}.py::{c.get('name')}")
             for c in suite.iter("testcase")]
print("\n======== run_tests.sh: the 20 slowest tests of the run (setup, call and teardown) ========")
for t, name in sorted(rows, reverse=True)[:20]:
    print(f"{t:8.2f}s {name}")
print("; ".join(parts))
EOF
if ((${#failed[@]})); then
    echo "run_tests.sh: failures in part ${failed[*]} (each part's summary above)" >&2
    exit 1
fi

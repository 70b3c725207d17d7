#!/usr/bin/env bash
# Runs every MECH test: installs missing system packages, builds both
# binaries (the end-to-end tests run them) and every test, then runs the
# tests in three lanes at once, then the Foxglove live view, which is built
# only with mech-station's `foxglove` feature (mech-gcs's forwards to it).
#
# The lanes: the fault-injection suite (real-time scenarios, one after
# another, mostly waiting), the end-to-end tests (real processes, mostly
# waiting) and every other crate's tests (most of the CPU). Each lane's
# output is printed whole when it ends; the script ends with the time each
# step took and fails if any test failed.
#
#   bash scripts/test.sh            the suite
#   bash scripts/test.sh --stress   the suite with a CPU hog per core beside
#                                   it for the whole run (build included), as
#                                   a busy machine or CI runner has; the hogs
#                                   end with the script, failed or not
set -euo pipefail
cd "$(dirname "$0")/.."

stress=false
for arg in "$@"; do
    case "$arg" in
    --stress) stress=true ;;
    *)
        echo "usage: bash scripts/test.sh [--stress]" >&2
        exit 2
        ;;
    esac
done

# Background jobs (hogs, lanes) each get a process group of their own
# (job control on while they start), so that ending the script ends them
# and every process they started.
background=()
spawn() {
    set -m
    "$@" &
    background+=($!)
    set +m
}
logs=$(mktemp -d)
finish() {
    for pid in "${background[@]}"; do
        kill -- "-$pid" 2>/dev/null || true
    done
    wait 2>/dev/null || true
    rm -rf "$logs"
}
trap finish EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

hog() { while :; do :; done; }
if $stress; then
    for _ in $(seq "$(nproc)"); do
        spawn hog
    done
    echo "stress: $(nproc) CPU hogs beside the suite"
fi

timings=()
started=$SECONDS
step() {
    local name=$1 t0=$SECONDS
    shift
    "$@"
    timings+=("$(printf '%5d s  %s' $((SECONDS - t0)) "$name")")
}

step "system packages" bash scripts/deps.sh
step "build: binaries" cargo build --workspace --bins
step "build: tests" cargo test --workspace --no-run

# Every lane selects the workspace (`--workspace`, or `--exclude`), so each
# resolves features as the builds above did and builds nothing again.
lane_names=(faults e2e crates)
lane_faults() { cargo test --workspace --test faults; }
lane_e2e() { cargo test --workspace --no-fail-fast --test e2e --test layout; }
lane_crates() { cargo test --workspace --no-fail-fast --exclude mech-e2e; }
lane() {
    local rc=0
    "lane_$1" >"$logs/$1.log" 2>&1 || rc=$?
    echo "$rc $((SECONDS - lanes_started))" >"$logs/$1.end"
}
lanes_started=$SECONDS
declare -A lane_pid
for name in "${lane_names[@]}"; do
    spawn lane "$name"
    lane_pid[$name]=${background[-1]}
done
echo "tests: lanes ${lane_names[*]} run at once (logs in $logs)"
failed=()
for name in "${lane_names[@]}"; do
    wait "${lane_pid[$name]}" || true
    echo "=== $name ==="
    cat "$logs/$name.log"
    read -r rc took <"$logs/$name.end" || { rc=1; took=0; }
    [ "$rc" -eq 0 ] || failed+=("$name")
    timings+=("$(printf '%5d s  tests: %s' "$took" "$name")")
done
timings+=("$(printf '%5d s  tests: all lanes' $((SECONDS - lanes_started)))")

# After the lanes: this build replaces target/debug/mech-gcs, which the
# end-to-end tests run, with the Foxglove build.
fox=0
step "foxglove (build and test)" cargo test --workspace \
    --features mech-station/foxglove,mech-gcs/foxglove --test foxglove_live || fox=$?
[ "$fox" -eq 0 ] || failed+=(foxglove)

echo
echo "time:"
printf '  %s\n' "${timings[@]}"
printf '%7d s  total\n' $((SECONDS - started))
if [ ${#failed[@]} -gt 0 ]; then
    echo "FAILED: ${failed[*]}"
    exit 1
fi
echo "all tests passed"

#!/usr/bin/env bash
# Runs every MECH test: installs missing system packages, builds both
# binaries (the end-to-end tests run them) and every test, runs the whole
# workspace's tests (every failing test binary, not only the first), then
# the Foxglove live view, which is built only with mech-station's `foxglove`
# feature (mech-gcs's forwards to it). Before the workspace, the binaries
# for a Raspberry Pi's processors and the Debian packages are built
# (scripts/cross.sh) and the packages checked (scripts/check-packages.sh):
# the end-to-end test `cross` runs those binaries under qemu. Ends with the
# time each step took; fails if any step or test failed.
#
# The tests run in one `cargo test --workspace`: a run of a part of the
# workspace (`--exclude`, or only some `--test` targets) resolves other
# features for the shared crates (dev-dependencies count only for the
# targets built), so it builds the workspace a second time (16 min beside
# other builds, measured).
#
#   bash scripts/test.sh            the suite
#   bash scripts/test.sh --stress   the suite with a CPU hog per core beside
#                                   it for the whole run (build included), as
#                                   a busy machine or CI runner has; the hogs
#                                   end with the script, failed or not
#   bash scripts/test.sh --no-cross without the cross builds and packages
#                                   (about 12 minutes less; the `cross` test
#                                   then says it skipped them, and fails
#                                   under CI)
set -euo pipefail
cd "$(dirname "$0")/.."

stress=false
cross=true
for arg in "$@"; do
    case "$arg" in
    --stress) stress=true ;;
    --no-cross) cross=false ;;
    *)
        echo "usage: bash scripts/test.sh [--stress] [--no-cross]" >&2
        exit 2
        ;;
    esac
done

# The hogs each get a process group of their own (job control on while
# they start), so that ending the script ends them.
background=()
spawn() {
    set -m
    "$@" &
    background+=($!)
    set +m
}
finish() {
    for pid in "${background[@]}"; do
        kill -- "-$pid" 2>/dev/null || true
    done
    wait 2>/dev/null || true
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
    local name=$1 t0=$SECONDS rc=0
    shift
    "$@" || rc=$?
    timings+=("$(printf '%5d s  %s' $((SECONDS - t0)) "$name")")
    return "$rc"
}

step "system packages" bash scripts/deps.sh

failed=()
if $cross; then
    rc=0
    step "cross: Pi binaries and packages" bash scripts/cross.sh || rc=$?
    if [ "$rc" -eq 0 ]; then
        # The end-to-end test `cross` must then run them, not skip them.
        export MECH_CROSS_REQUIRED=1
        step "packages: install and check" bash scripts/check-packages.sh || rc=$?
        [ "$rc" -eq 0 ] || failed+=(packages)
    else
        failed+=(cross)
    fi
fi

# The agent with its ROS 2 base platform (feature `ros2`): its unit tests
# run, and the end-to-end tests drive a ROS 2 base with it
# (gcs-tui/ros2/tests/base.rs). One feature set for every step, so each
# builds on the one before.
features=mech-agent/ros2
step "build: binaries" cargo build --workspace --bins --features "$features"
step "build: tests" cargo test --workspace --no-run --features "$features"

tests=0
rm -f target/cross/emulated.log
step "tests" cargo test --workspace --no-fail-fast --features "$features" || tests=$?
[ "$tests" -eq 0 ] || failed+=(tests)
# What the Pi binaries did under qemu (the test `cross` writes it).
if [ -f target/cross/emulated.log ]; then
    echo
    echo "the Pi binaries under qemu (tests/e2e/cross.rs):"
    sed 's/^/  /' target/cross/emulated.log
fi

# Last: this build replaces target/debug/mech-gcs, which the end-to-end
# tests run, with the Foxglove build.
fox=0
step "foxglove (build and test)" cargo test --workspace \
    --features "$features,mech-station/foxglove,mech-gcs/foxglove" --test foxglove_live || fox=$?
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

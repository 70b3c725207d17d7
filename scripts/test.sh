#!/usr/bin/env bash
# Runs every MECH test: installs missing system packages, builds both
# binaries (the end-to-end tests run them), then the whole workspace's tests,
# then the Foxglove live view, which is built only with mech-station's
# `foxglove` feature (mech-gcs's forwards to it): the view in mech-station,
# and the mech-gcs binary serving it (a second build of both).
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

hogs=()
stop_hogs() {
    if [ ${#hogs[@]} -gt 0 ]; then
        kill "${hogs[@]}" 2>/dev/null || true
        wait "${hogs[@]}" 2>/dev/null || true
        hogs=()
    fi
}
trap stop_hogs EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
if $stress; then
    cores=$(nproc)
    for _ in $(seq "$cores"); do
        (while :; do :; done) &
        hogs+=($!)
    done
    echo "stress: ${#hogs[@]} CPU hogs beside the suite (pids ${hogs[*]})"
fi

bash scripts/deps.sh
cargo build --workspace --bins
cargo test --workspace --no-fail-fast
cargo test -p mech-station --features foxglove --test foxglove_live
cargo test -p mech-gcs --features foxglove --test foxglove_live

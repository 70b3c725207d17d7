#!/usr/bin/env bash
# Runs every MECH test: installs missing system packages, builds both
# binaries (the end-to-end tests run them), then the whole workspace's tests,
# then the Foxglove live view, which is built only with mech-gcs's
# `foxglove` feature (a second build of mech-gcs).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo build --workspace --bins
cargo test --workspace
cargo test -p mech-gcs --features foxglove --test foxglove_live

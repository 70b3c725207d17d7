#!/usr/bin/env bash
# Runs every MECH test: installs missing system packages, builds both
# binaries (the end-to-end tests run them), then the whole workspace's tests,
# then the Foxglove live view, which is built only with mech-station's
# `foxglove` feature (mech-gcs's forwards to it): the view in mech-station,
# and the mech-gcs binary serving it (a second build of both).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo build --workspace --bins
cargo test --workspace
cargo test -p mech-station --features foxglove --test foxglove_live
cargo test -p mech-gcs --features foxglove --test foxglove_live

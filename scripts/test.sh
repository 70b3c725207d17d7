#!/usr/bin/env bash
# Runs every MECH test: installs missing system packages, builds both
# binaries (the end-to-end tests run them), then the whole workspace's tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo build --workspace --bins
cargo test --workspace

#!/usr/bin/env bash
# Runs the MECH ground station with a simulated fleet: installs missing system
# packages, builds in release mode, starts `mech-gcs --demo`. Extra arguments
# are passed on (e.g. `bash scripts/demo.sh 8` for eight robots).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo build --release -p mech-gcs -p mech-agent
exec target/release/mech-gcs --demo "$@"

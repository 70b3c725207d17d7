#!/usr/bin/env bash
# Runs the MECH ground station with a simulated fleet: installs the few
# system packages the build needs (scripts/deps-demo.sh; the tests' tools
# are not installed here), builds mech-gcs with the `demo` profile (no LTO,
# dependencies optimised, MECH's crates lightly: minutes from a fresh clone
# on two cores, see Cargo.toml) and starts `mech-gcs --demo`, whose
# simulated robots run inside it. Extra arguments are passed on (e.g.
# `bash scripts/demo.sh 8` for eight robots).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps-demo.sh
cargo build --profile demo -p mech-gcs
exec target/demo/mech-gcs --demo "$@"

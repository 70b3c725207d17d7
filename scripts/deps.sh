#!/usr/bin/env bash
# Installs what MECH's tests need on a fresh Debian/Ubuntu machine: first
# what the demo needs (scripts/deps-demo.sh: libudev-dev + pkg-config for
# gilrs and serialport), then socat (serial-link tests over a
# pseudo-terminal pair), nftables and iproute2 (the fault-injection suite's
# packet loss in network namespaces), tmux (the end-to-end TUI test), strace
# (the replay test checks that a replay opens no socket), qemu-user (the
# binaries built for a Raspberry Pi's processors run under it), GNU Octave with its
# instrument-control package (the tests run the Octave example; about a
# minute to install once, without recommended packages), Python's msgpack
# (the Python client and the documented controller), pymavlink (the fake
# autopilot the MAVLink tests fly against), Python's mcap (the recording
# test reads recordings with it), jsonschema (the recording test validates
# every message against the schema the file embeds), eclipse-zenoh (the
# documented reader of MECH's robots on Zenoh) and cyclonedds (the ROS 2 node
# the bridge's tests talk to; its wheel carries Cyclone DDS itself). Does
# nothing when they are
# already there.
set -euo pipefail
bash "$(dirname "$0")/deps-demo.sh"
need=()
for pkg in socat nftables iproute2 tmux strace qemu-user octave octave-instrument-control; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    sudo_cmd=""
    [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
# Python packages the tests use, each only when missing.
pip_install() {
    python3 -m pip install --quiet --disable-pip-version-check "$1" 2>/dev/null \
        || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages "$1"
}
if command -v python3 >/dev/null; then
    if ! python3 -c 'import msgpack' 2>/dev/null; then
        echo "installing: python msgpack"
        pip_install msgpack
    fi
    if ! python3 -c 'import pymavlink' 2>/dev/null; then
        echo "installing: python pymavlink"
        pip_install pymavlink==2.4.50
    fi
    # Python's mcap (with its zstd and lz4): an independent reader of recordings.
    if ! python3 -c 'import mcap' 2>/dev/null; then
        echo "installing: python mcap"
        pip_install mcap
    fi
    # Python's jsonschema: an independent validator of the recordings.
    if ! python3 -c 'import jsonschema' 2>/dev/null; then
        echo "installing: python jsonschema"
        pip_install jsonschema
    fi
    # Python's Zenoh, the version of the Rust crate: the documented reader
    # of MECH's robots on Zenoh runs in the tests.
    if ! python3 -c 'import zenoh' 2>/dev/null; then
        echo "installing: python eclipse-zenoh"
        pip_install eclipse-zenoh==1.10.2
    fi
    # Cyclone DDS's Python binding: an independent DDS acting as a ROS 2
    # node in mech-ros2's end-to-end tests.
    if ! python3 -c 'import cyclonedds.domain' 2>/dev/null; then
        echo "installing: python cyclonedds"
        pip_install cyclonedds==11.0.1
    fi
fi

#!/usr/bin/env bash
# Installs what MECH needs on a fresh Debian/Ubuntu machine: libudev-dev +
# pkg-config (gilrs, serialport), socat (serial-link tests over a
# pseudo-terminal pair), tmux (the end-to-end TUI test), and Python's msgpack
# and eclipse-zenoh (the documented Python controller and Zenoh reader are
# run by the tests). Does nothing when they are already there.
set -euo pipefail
need=()
for pkg in libudev-dev pkg-config socat tmux; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    sudo_cmd=""
    [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${need[@]}" >/dev/null
fi
# Python's msgpack: the documented Python controller runs in the tests.
if command -v python3 >/dev/null && ! python3 -c 'import msgpack' 2>/dev/null; then
    echo "installing: python msgpack"
    python3 -m pip install --quiet --disable-pip-version-check msgpack 2>/dev/null \
        || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages msgpack
fi
# Python's Zenoh (the version of the Rust crate): the documented reader of
# MECH's robots on Zenoh runs in the tests.
if command -v python3 >/dev/null && ! python3 -c 'import zenoh' 2>/dev/null; then
    echo "installing: python eclipse-zenoh"
    python3 -m pip install --quiet --disable-pip-version-check 'eclipse-zenoh==1.10.2' 2>/dev/null \
        || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages 'eclipse-zenoh==1.10.2'
fi

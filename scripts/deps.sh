#!/usr/bin/env bash
# Installs what MECH needs on a fresh Debian/Ubuntu machine: libudev-dev +
# pkg-config (gilrs, serialport), socat (serial-link tests over a
# pseudo-terminal pair), nftables and iproute2 (the fault-injection suite's
# packet loss in network namespaces), tmux (the end-to-end TUI test), and Python's msgpack
# (the documented Python controller is run by the tests). Does nothing when
# they are already there.
set -euo pipefail
need=()
for pkg in libudev-dev pkg-config socat nftables iproute2 tmux; do
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

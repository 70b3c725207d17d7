#!/usr/bin/env bash
# Installs what the demo needs to build on a fresh Debian/Ubuntu machine:
# libudev-dev and pkg-config (gamepads through gilrs, serial ports through
# serialport). Nothing else: the tests' tools are scripts/deps.sh's.
# Does nothing when they are already there.
set -euo pipefail
need=()
for pkg in libudev-dev pkg-config; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    sudo_cmd=""
    [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

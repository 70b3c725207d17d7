#!/usr/bin/env bash
# Installs the system packages MECH needs on a fresh Debian/Ubuntu machine:
# libudev-dev + pkg-config (gilrs, serialport), socat (serial-link tests over a
# pseudo-terminal pair), tmux (the end-to-end TUI test). Does nothing when
# they are already there.
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

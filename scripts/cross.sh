#!/usr/bin/env bash
# Builds MECH for the processors robots have, and its Debian packages:
# mech-agent for arm64 (aarch64: Raspberry Pi 3, 4 and 5 on 64-bit
# Raspberry Pi OS), armhf (armv7: 32-bit Raspberry Pi OS) and amd64;
# mech-gcs for arm64 (a Pi 5 as the station of a small fleet) and amd64.
# Builds of the `dist` profile (release without link-time optimisation,
# stripped: Cargo.toml), each agent with GPIO (`rpi`), ROS 2 bases (`ros2`), serial ports
# and MAVLink; then `mech-agent_*.deb` and `mech-gcs_*.deb` per
# architecture, made by cargo-deb, under target/cross/debian/.
#
# The compiler is Debian's: rustup has no standard library for these
# targets here, but Debian trixie ships Rust with one for arm64 and armhf.
# Its `rustc` (1.85) is older than the MAVLink crate allows (1.88), so the
# build uses trixie's `rustc-web` (1.96), the toolchain Debian keeps
# current in its stable release for the browsers, with
# `libstd-rust-web-dev` for each architecture, the gcc cross compilers
# and libudev for each. It needs trixie's C library, so it runs in a
# trixie root (mmdebstrap, about 1.9 GB, target/cross/root, made once and
# kept while its package list is the same). The root's cargo downloads
# the crates into the host's cargo cache.
# Everything it mounts lives in a mount namespace of its own, gone when it
# ends, failed or not. Needs root (apt-get, mmdebstrap, chroot).
#
# The agents ask for glibc 2.35 at most (checked below), so they run on
# Raspberry Pi OS bookworm (glibc 2.36) and trixie alike; the arm64
# station needs trixie. The amd64 binaries are built on the host, with
# its Rust toolchain (rustup's, as for the rest of MECH).
#
#   bash scripts/cross.sh            root, builds, packages
#   bash scripts/cross.sh --no-deb   root and builds only
#
# Then `bash scripts/check-packages.sh` installs and inspects the
# packages, and the end-to-end test `cross` (tests/e2e/cross.rs) runs
# the arm binaries under qemu against the station.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=true
for arg in "$@"; do
    case "$arg" in
    --no-deb) packages=false ;;
    *)
        echo "usage: bash scripts/cross.sh [--no-deb]" >&2
        exit 2
        ;;
    esac
done

if [ "$(id -u)" -ne 0 ]; then
    echo "scripts/cross.sh needs root (apt-get, mmdebstrap, chroot): run it with sudo" >&2
    exit 2
fi

out=target/cross
root=$out/root
cargo_deb_version=3.7.0
# What the root holds: the toolchain and, for each architecture, its
# standard library, C compiler and libudev; dpkg-dev (dpkg-shlibdeps
# works out each package's library dependencies) and lintian (the
# packages' check).
root_packages=(
    rustc-web cargo-web gcc libc6-dev libudev-dev pkg-config ca-certificates
    libstd-rust-web-dev:arm64 gcc-aarch64-linux-gnu libc6-dev:arm64 libudev-dev:arm64
    libstd-rust-web-dev:armhf gcc-arm-linux-gnueabihf libc6-dev:armhf libudev-dev:armhf
    dpkg-dev lintian
)
mirror=http://deb.debian.org/debian

step_started=$SECONDS
say() { printf '[cross %4d s] %s\n' $((SECONDS - step_started)) "$*"; }

# amd64 first, on the host with the machine's own Rust toolchain (see
# below), and cargo-deb beside it: neither needs the root, so both compile
# while the root is made (mostly downloads). Stopped with the script,
# failed or not.
CARGO_TARGET_DIR="$out/build-amd64" cargo build --profile dist --locked --quiet \
    --features mech-agent/rpi,mech-agent/ros2 --target x86_64-unknown-linux-gnu -p mech-agent -p mech-gcs &
amd64=$!
# cargo-deb, the one packaging tool (Debian package metadata stays in the
# crates' Cargo.toml, [package.metadata.deb]), built by the host's
# toolchain (unoptimised: it packs five packages, and builds in a third of
# the time; it needs glibc 2.36, so it runs in the trixie root too).
tools=$out/tools
cargo_deb=
if ! "$tools/bin/cargo-deb" --version 2>/dev/null | grep -q "$cargo_deb_version"; then
    cargo install --quiet --locked --debug cargo-deb --version "$cargo_deb_version" \
        --root "$tools" &
    cargo_deb=$!
fi
trap 'kill $amd64 $cargo_deb 2>/dev/null || true' EXIT

# The host's tools: mmdebstrap makes the root.
if ! command -v mmdebstrap >/dev/null; then
    say "installing mmdebstrap"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends mmdebstrap >/dev/null
fi

# The root, made again only when its package list changes.
want="trixie ${root_packages[*]}"
if [ "$(cat "$root/.mech-root" 2>/dev/null)" != "$want" ]; then
    say "making the trixie build root (${#root_packages[@]} packages)"
    rm -rf "$root" "$root.tmp"
    mkdir -p "$out"
    include=$(
        IFS=,
        echo "${root_packages[*]}"
    )
    mmdebstrap --quiet --variant=apt --architectures=amd64,arm64,armhf \
        --include="$include" trixie "$root.tmp" "$mirror"
    echo "$want" >"$root.tmp/.mech-root"
    mv "$root.tmp" "$root"
fi
mkdir -p "$root/src" "$root/cargo"

# The cargo cache is the host's (crates downloaded once serve both), the
# name server and certificate authorities too (a network whose proxy has
# its own authority works from the root as from the host).
cargo_home=${CARGO_HOME:-$HOME/.cargo}
mkdir -p "$cargo_home"
cp /etc/resolv.conf "$root/etc/resolv.conf"
cainfo=
if [ -f /etc/ssl/certs/ca-certificates.crt ]; then
    cp /etc/ssl/certs/ca-certificates.crt "$root/etc/ssl/certs/host-ca-certificates.crt"
    cainfo=/etc/ssl/certs/host-ca-certificates.crt
fi

# Runs a command in the root, the source at /src and the cargo cache at
# /cargo, in a mount namespace of its own (its mounts end with it).
in_root() {
    unshare --mount --propagation private -- /bin/sh -euc '
        root=$1 src=$2 cargo=$3 cainfo=$4
        shift 4
        mount --bind "$src" "$root/src"
        mount --bind "$cargo" "$root/cargo"
        mount -t proc proc "$root/proc"
        mount --bind /dev "$root/dev"
        exec chroot "$root" /usr/bin/env -i \
            PATH=/usr/bin:/bin HOME=/root CARGO_HOME=/cargo \
            ${cainfo:+CARGO_HTTP_CAINFO=$cainfo} \
            CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
            CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_LINKER=arm-linux-gnueabihf-gcc \
            CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc \
            CC_armv7_unknown_linux_gnueabihf=arm-linux-gnueabihf-gcc \
            PKG_CONFIG_ALLOW_CROSS=1 \
            PKG_CONFIG_LIBDIR_aarch64_unknown_linux_gnu=/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig \
            PKG_CONFIG_LIBDIR_armv7_unknown_linux_gnueabihf=/usr/lib/arm-linux-gnueabihf/pkgconfig:/usr/share/pkgconfig \
            "$@"
    ' in_root "$PWD/$root" "$PWD" "$cargo_home" "$cainfo" "$@"
}

# The arm builds in the root, one after the other, each with a target
# directory of its own, once the amd64 build and cargo-deb are done: each
# build keeps both cores busy by itself, and three side by side took 47%
# more CPU time than one after another (2,035 CPU-s for the whole step
# against 1,380: 1,054 s against 725 s), with memory to spare. The amd64
# binaries are built on the host, with the machine's own Rust toolchain:
# they take the host's C library (the packages are checked on Debian
# bookworm: build them on bookworm), and its compiler builds them in about
# half the CPU time Debian's takes.
failed=()
wait "$amd64" || failed+=(amd64)
[ -z "$cargo_deb" ] || wait "$cargo_deb" || failed+=(cargo-deb)
say "building: arm64 (mech-agent, mech-gcs)"
in_root /usr/bin/env CARGO_TARGET_DIR="/src/$out/build" /bin/sh -c \
    'cd /src && cargo build --profile dist --locked --quiet --features mech-agent/rpi,mech-agent/ros2 \
        --target aarch64-unknown-linux-gnu -p mech-agent -p mech-gcs' || failed+=(arm64)
say "building: armhf (mech-agent)"
in_root /usr/bin/env CARGO_TARGET_DIR="/src/$out/build-armhf" /bin/sh -c \
    'cd /src && cargo build --profile dist --locked --quiet --features rpi,ros2 \
        --target armv7-unknown-linux-gnueabihf -p mech-agent' || failed+=(armhf)
[ ${#failed[@]} -eq 0 ] || {
    echo "cross build failed: ${failed[*]}" >&2
    exit 1
}
# One place for every target's binaries (where cargo-deb looks).
for triple in armv7-unknown-linux-gnueabihf:build-armhf:mech-agent \
    x86_64-unknown-linux-gnu:build-amd64:mech-agent x86_64-unknown-linux-gnu:build-amd64:mech-gcs; do
    IFS=: read -r t dir bin <<<"$triple"
    mkdir -p "$out/build/$t/dist"
    cp "$out/$dir/$t/dist/$bin" "$out/build/$t/dist/$bin"
done

# What each binary is, its size and the newest glibc symbol it needs. The
# agents must run on Raspberry Pi OS bookworm (glibc 2.36) and trixie. The
# arm64 station needs trixie (2.41): Debian's standard library for these
# targets calls glibc 2.39's pidfd_spawnp to start processes, which the
# station does (a trixie Pi is the station MECH describes). The amd64 ones
# take the host's glibc: past 2.36, they will not install on bookworm, and
# this says so.
newest() { readelf -W --dyn-syms "$1" | grep -o 'GLIBC_[0-9.]*' | sort -uV | tail -1; }
at_most() { [ "$(printf '%s\n%s\n' "$1" "$2" | sort -V | tail -1)" = "$2" ]; }
for entry in aarch64-unknown-linux-gnu:mech-agent:GLIBC_2.36 \
    armv7-unknown-linux-gnueabihf:mech-agent:GLIBC_2.36 \
    aarch64-unknown-linux-gnu:mech-gcs:GLIBC_2.41 \
    x86_64-unknown-linux-gnu:mech-agent:host x86_64-unknown-linux-gnu:mech-gcs:host; do
    IFS=: read -r triple bin limit <<<"$entry"
    f=$out/build/$triple/dist/$bin
    glibc=$(newest "$f")
    printf '  %-32s %-10s %6d KiB  needs %s\n' "$triple" "$bin" $(($(stat -c %s "$f") / 1024)) "$glibc"
    if [ "$limit" = host ]; then
        at_most "$glibc" GLIBC_2.36 ||
            echo "  (built on a host with a newer glibc: $bin for amd64 needs $glibc, newer than bookworm's)"
    elif ! at_most "$glibc" "$limit"; then
        echo "$f needs $glibc; it must run with $limit" >&2
        exit 1
    fi
done

$packages || exit 0

# The packages, made in the root: dpkg-shlibdeps there knows each
# architecture's libraries, so each package's Depends is its own.
say "packaging"
rm -rf "$out/debian"
mkdir -p "$out/debian"
for pair in mech-agent:x86_64-unknown-linux-gnu mech-agent:aarch64-unknown-linux-gnu \
    mech-agent:armv7-unknown-linux-gnueabihf mech-gcs:x86_64-unknown-linux-gnu \
    mech-gcs:aarch64-unknown-linux-gnu; do
    package=${pair%%:*} triple=${pair#*:}
    in_root /usr/bin/env CARGO_TARGET_DIR="/src/$out/build" /bin/sh -c \
        "cd /src && /src/$tools/bin/cargo-deb --quiet --no-build --no-strip --profile dist \
            -p $package --target $triple --output /src/$out/debian/"
done
ls -l "$out/debian"
say "done"

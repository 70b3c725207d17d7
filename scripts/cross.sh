#!/usr/bin/env bash
# Builds MECH for the processors robots have, and its Debian packages:
# mech-agent for arm64 (aarch64: Raspberry Pi 3, 4 and 5 on 64-bit
# Raspberry Pi OS), armhf (armv7: 32-bit Raspberry Pi OS) and amd64;
# mech-gcs for arm64 (a Pi 5 as the station of a small fleet) and amd64.
# Builds of the `dist` profile (release without link-time optimisation,
# stripped: Cargo.toml), each agent with GPIO (`rpi`), serial ports
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
# kept while its package list is the same). No Rust is needed on the
# host: the root's cargo downloads the crates, into the host's cargo cache.
# Everything it mounts lives in a mount namespace of its own, gone when it
# ends, failed or not. Needs root (apt-get, mmdebstrap, chroot).
#
# The binaries ask for glibc 2.35 at most (checked below), so they run on
# Raspberry Pi OS bookworm (glibc 2.36) and trixie alike.
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
# cargo-deb, the one packaging tool: Debian package metadata stays in the
# crates' Cargo.toml ([package.metadata.deb]).
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

# cargo-deb, built by the root's toolchain (unoptimised: it packs five
# packages, and builds in half the time).
tools=$out/tools
if ! in_root "/src/$tools/bin/cargo-deb" --version 2>/dev/null | grep -q "$cargo_deb_version"; then
    say "building cargo-deb $cargo_deb_version"
    in_root cargo install --quiet --locked --debug cargo-deb --version "$cargo_deb_version" \
        --root "/src/$tools"
fi

# Two builds side by side, so that one's linking overlaps the other's
# compiling: amd64 and arm64 (agent and station) in one, armhf (agent) in
# the other, each with a target directory of its own.
say "building: amd64 and arm64 (mech-agent, mech-gcs), armhf (mech-agent)"
in_root /usr/bin/env CARGO_TARGET_DIR="/src/$out/build" /bin/sh -c \
    'cd /src && cargo build --profile dist --locked --quiet --features mech-agent/rpi \
        --target x86_64-unknown-linux-gnu --target aarch64-unknown-linux-gnu \
        -p mech-agent -p mech-gcs' &
first=$!
in_root /usr/bin/env CARGO_TARGET_DIR="/src/$out/build-armhf" /bin/sh -c \
    'cd /src && cargo build --profile dist --locked --quiet --features rpi \
        --target armv7-unknown-linux-gnueabihf -p mech-agent' &
second=$!
failed=0
wait "$first" || failed=1
wait "$second" || failed=1
[ "$failed" -eq 0 ] || {
    echo "cross build failed" >&2
    exit 1
}
# One place for every target's binaries.
mkdir -p "$out/build/armv7-unknown-linux-gnueabihf/dist"
cp "$out/build-armhf/armv7-unknown-linux-gnueabihf/dist/mech-agent" \
    "$out/build/armv7-unknown-linux-gnueabihf/dist/mech-agent"

# What each binary is, its size and the newest glibc symbol it needs.
for triple in x86_64-unknown-linux-gnu aarch64-unknown-linux-gnu armv7-unknown-linux-gnueabihf; do
    for bin in mech-agent mech-gcs; do
        f=$out/build/$triple/dist/$bin
        [ -f "$f" ] || continue
        glibc=$(readelf -W --dyn-syms "$f" | grep -o 'GLIBC_[0-9.]*' | sort -uV | tail -1)
        printf '  %-32s %-10s %6d KiB  needs %s\n' "$triple" "$bin" $(($(stat -c %s "$f") / 1024)) "$glibc"
        case "$glibc" in
        GLIBC_2.3[0-6] | GLIBC_2.[12][0-9] | GLIBC_2.[0-9]) ;;
        *)
            echo "$f needs $glibc: Raspberry Pi OS bookworm has glibc 2.36" >&2
            exit 1
            ;;
        esac
    done
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

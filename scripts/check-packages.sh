#!/usr/bin/env bash
# Checks the Debian packages `scripts/cross.sh` made (target/cross/debian/):
#
# - each amd64 package is installed with dpkg into a clean Debian bookworm
#   root (the oldest Raspberry Pi OS base in use), with only systemd and
#   adduser beside the minimal system: its files, the `mech` system user,
#   /etc/mech/keys readable by that user alone, both units verified by
#   `systemd-analyze verify`, and each installed binary's `--check` run as
#   that user on the installed configuration (the agent's names the GPIO
#   and serial port this machine lacks; the station's names the keys it
#   lacks, then passes once they are made as it says); then both are
#   purged;
# - the arm packages are inspected (contents, architecture, dependencies)
#   and their agent, unpacked, runs under qemu (`--version`, `--check`);
# - lintian judges every package; an error fails the check, warnings are
#   printed (docs/packages.md says why those that stay, stay).
#
# Needs root (mmdebstrap, chroot). Every mount lives in a mount namespace
# of its own; the clean root is deleted at the end, failed or not.
set -euo pipefail
cd "$(dirname "$0")/.."

out=target/cross
debs=$out/debian
build_root=$out/root
clean=$out/clean-root
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)
deb() { echo "$debs/${1}_${version}-1_${2}.deb"; }

for p in mech-agent_amd64 mech-agent_arm64 mech-agent_armhf mech-gcs_amd64 mech-gcs_arm64; do
    f=$(deb "${p%_*}" "${p#*_}")
    [ -f "$f" ] || {
        echo "missing $f: run bash scripts/cross.sh first" >&2
        exit 1
    }
done

failures=()
fail() {
    echo "FAIL: $*"
    failures+=("$*")
}
started=$SECONDS
say() { printf '[packages %4d s] %s\n' $((SECONDS - started)) "$*"; }

# Runs a command in `root` with /proc and /dev, in a mount namespace.
run_in() {
    local root=$1
    shift
    unshare --mount --propagation private -- /bin/sh -euc '
        root=$1
        shift
        mount -t proc proc "$root/proc"
        mount --bind /dev "$root/dev"
        exec chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 "$@"
    ' run_in "$root" "$@"
}

cleanup() { rm -rf "$clean"; }
trap cleanup EXIT

# --- the arm packages: contents, architecture, their agent under qemu ---
for arch in arm64 armhf; do
    f=$(deb mech-agent "$arch")
    got=$(dpkg-deb -f "$f" Architecture)
    [ "$got" = "$arch" ] || fail "$f: Architecture $got, expected $arch"
    say "$(basename "$f"): Depends: $(dpkg-deb -f "$f" Depends)"
    dpkg-deb -c "$f" | awk '{print "    " $1, $2, $6}'
    unpacked=$(mktemp -d)
    dpkg-deb -x "$f" "$unpacked"
    qemu=qemu-aarch64
    [ "$arch" = armhf ] && qemu=qemu-arm
    if ! "$qemu" -L "$build_root" "$unpacked/usr/bin/mech-agent" --version; then
        fail "$arch agent from the package does not run under qemu"
    fi
    set +e
    check=$("$qemu" -L "$build_root" "$unpacked/usr/bin/mech-agent" \
        --config "$unpacked/etc/mech/agent.toml" --check 2>&1)
    rc=$?
    set -e
    echo "$check" | sed 's/^/    /'
    if [ $rc -ne 1 ] || ! grep -q '^  GPIO 6, 12, 20, 13, 19, 26 (actuators: L298): ' <<<"$check" ||
        ! grep -q '^  serial port /dev/ttyACM0 at 115200 baud (position: Pozyx): ' <<<"$check" ||
        [ "$(wc -l <<<"$check")" -ne 3 ]; then
        fail "$arch agent --check of the packaged config: exit $rc"
    fi
    rm -rf "$unpacked"
done
f=$(deb mech-gcs arm64)
got=$(dpkg-deb -f "$f" Architecture)
[ "$got" = arm64 ] || fail "$f: Architecture $got, expected arm64"
say "$(basename "$f"): Depends: $(dpkg-deb -f "$f" Depends)"
dpkg-deb -c "$f" | awk '{print "    " $1, $2, $6}' | head -12

# --- the amd64 packages, installed into a clean bookworm ---
say "making a clean Debian bookworm root"
rm -rf "$clean"
mmdebstrap --quiet --variant=minbase --include=systemd,adduser bookworm "$clean" \
    http://deb.debian.org/debian
cp "$(deb mech-agent amd64)" "$(deb mech-gcs amd64)" "$clean/tmp/"
say "dpkg -i mech-agent and mech-gcs"
run_in "$clean" dpkg -i "/tmp/$(basename "$(deb mech-agent amd64)")" \
    "/tmp/$(basename "$(deb mech-gcs amd64)")" || fail "dpkg -i"
for pkg in mech-agent mech-gcs; do
    run_in "$clean" dpkg -L "$pkg" | sed "s/^/    $pkg: /"
done
for path in /usr/bin/mech-agent /usr/bin/mech-gcs /etc/mech/agent.toml /etc/mech/gcs.toml \
    /lib/systemd/system/mech-agent.service /lib/systemd/system/mech-gcs.service; do
    [ -e "$clean$path" ] || fail "$path is not installed"
done
# The configuration files are conffiles: an upgrade keeps a robot's edits.
for pkg in mech-agent:agent mech-gcs:gcs; do
    run_in "$clean" dpkg-query -W -f='${Conffiles}\n' "${pkg%:*}" | grep -q "/etc/mech/${pkg#*:}.toml" ||
        fail "/etc/mech/${pkg#*:}.toml is not a conffile of ${pkg%:*}"
done
# The user: a system user without a login shell.
user=$(run_in "$clean" getent passwd mech || true)
say "user: $user"
IFS=: read -r _ _ uid _ _ _ shell <<<"$user"
if [ -z "$user" ] || [ "$uid" -ge 1000 ] || [ "$shell" != /usr/sbin/nologin ]; then
    fail "the mech user: '$user' (expected a system user with /usr/sbin/nologin)"
fi
keys=$(run_in "$clean" stat -c '%U:%G %a' /etc/mech/keys)
say "/etc/mech/keys: $keys"
[ "$keys" = "mech:mech 700" ] || fail "/etc/mech/keys is $keys, expected mech:mech 700"
# The units, as systemd reads them (the binaries they start, the user).
verify=$(run_in "$clean" systemd-analyze verify mech-agent.service mech-gcs.service 2>&1) ||
    fail "systemd-analyze verify: $verify"
echo "$verify" | sed 's/^/    verify: /'
[ -z "$verify" ] || fail "systemd-analyze verify said: $verify"
# The installed agent's --check, as the service runs it.
set +e
check=$(run_in "$clean" runuser -u mech -- mech-agent --config /etc/mech/agent.toml --check 2>&1)
rc=$?
set -e
echo "$check" | sed 's/^/    /'
if [ $rc -ne 1 ] || [ "$(wc -l <<<"$check")" -ne 3 ] ||
    ! grep -q '^  GPIO 6, 12, 20, 13, 19, 26 (actuators: L298): ' <<<"$check" ||
    ! grep -q '^  serial port /dev/ttyACM0 at 115200 baud (position: Pozyx): ' <<<"$check"; then
    fail "installed mech-agent --check: exit $rc, expected 1 naming the GPIO and the serial port"
fi
# The installed station's --check: the four keys of the example are
# missing; made as it says (as the mech user), it passes, and nobody
# else can read them.
set +e
check=$(run_in "$clean" runuser -u mech -- mech-gcs --config /etc/mech/gcs.toml --check 2>&1)
rc=$?
set -e
echo "$check" | sed 's/^/    /'
[ $rc -eq 1 ] && [ "$(grep -c 'does not exist; make it with' <<<"$check")" -eq 4 ] ||
    fail "installed mech-gcs --check: exit $rc, expected 1 naming four missing keys"
for name in robot_1 matlab operator button; do
    run_in "$clean" runuser -u mech -- mech-gcs keygen "$name" --out "/etc/mech/keys/$name.key" >/dev/null ||
        fail "keygen $name as mech"
done
mode=$(run_in "$clean" stat -c '%U %a' /etc/mech/keys/robot_1.key)
[ "$mode" = "mech 600" ] || fail "a key made as mech is '$mode', expected 'mech 600'"
if run_in "$clean" runuser -u nobody -- cat /etc/mech/keys/robot_1.key >/dev/null 2>&1; then
    fail "another user can read a key"
fi
check=$(run_in "$clean" runuser -u mech -- mech-gcs --config /etc/mech/gcs.toml --check 2>&1) ||
    fail "installed mech-gcs --check with its keys: $check"
echo "    $check"
# Purged, both go; the keys and the user stay.
run_in "$clean" dpkg --purge mech-agent mech-gcs >/dev/null || fail "dpkg --purge"
for path in /usr/bin/mech-agent /usr/bin/mech-gcs /etc/mech/agent.toml /etc/mech/gcs.toml; do
    [ ! -e "$clean$path" ] || fail "$path is still there after the purge"
done
[ -f "$clean/etc/mech/keys/robot_1.key" ] || fail "the purge deleted a key"

# --- lintian, in the build root (trixie's lintian) ---
say "lintian"
mkdir -p "$build_root/tmp/debs"
cp "$debs"/*.deb "$build_root/tmp/debs/"
inside=()
for f in "$debs"/*.deb; do inside+=("/tmp/debs/$(basename "$f")"); done
set +e
verdict=$(run_in "$build_root" lintian --fail-on error --tag-display-limit 0 "${inside[@]}" 2>&1)
rc=$?
set -e
rm -rf "$build_root/tmp/debs"
echo "$verdict" | grep -v '^running with root privileges' | sed 's/^/    /' || true
errors=$(grep -c '^E: ' <<<"$verdict" || true)
warnings=$(grep -c '^W: ' <<<"$verdict" || true)
say "lintian on ${#inside[@]} packages: $errors errors, $warnings warnings (exit $rc)"
[ "$rc" -eq 0 ] && [ "$errors" -eq 0 ] || fail "lintian: exit $rc, $errors errors"

if [ ${#failures[@]} -gt 0 ]; then
    printf 'package check FAILED:\n' >&2
    printf '  %s\n' "${failures[@]}" >&2
    exit 1
fi
say "packages: all checks passed"

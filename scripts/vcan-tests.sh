#!/usr/bin/env bash
# Runs the ATI CAN driver's integration tests on a real SocketCAN interface (vcan0):
# natively when this kernel has CAN support, otherwise inside User-Mode Linux (see
# shared/specs/vcan-in-uml.md). The test binary is built on the host and run in the guest via hostfs.
#
# Usage: scripts/vcan-tests.sh            (auto: native if possible, else UML)
#        FORCECELL_VCAN_MODE=uml|native scripts/vcan-tests.sh
# Exits non-zero, with a message that says why, when a prerequisite is missing or any test fails.
set -euo pipefail

cd "$(dirname "$0")/.."
root=$PWD
mode=${FORCECELL_VCAN_MODE:-auto}

die() {
  echo "vcan-tests: $*" >&2
  exit 1
}

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
    die "need root for: $* (run as root or install sudo)"
  fi
}

# ---- prerequisites ---------------------------------------------------------------------------
missing=()
command -v candump >/dev/null || missing+=(can-utils)
command -v ip >/dev/null || missing+=(iproute2)
if [ "$mode" != native ]; then
  command -v linux.uml >/dev/null || missing+=(user-mode-linux)
  # The guest loads the CAN modules with insmod (kmod), from the host's root filesystem.
  [ -x /usr/sbin/insmod ] || [ -x /sbin/insmod ] || missing+=(kmod)
fi
if ((${#missing[@]})); then
  command -v apt-get >/dev/null || die "missing ${missing[*]} and no apt-get to install them"
  echo "vcan-tests: installing ${missing[*]}"
  as_root apt-get update -qq || die "apt-get update failed"
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null ||
    die "apt-get install ${missing[*]} failed"
fi

# ---- build on the host -----------------------------------------------------------------------
# The driver-vs-node scenarios and can-utils interop (sim/tests/ati_vcan.rs) and the CLI's ATI commands
# (tests/ati_cli_vcan.rs). Their vcan tests are #[ignore]d in a plain `cargo test`.
echo "vcan-tests: building the test binaries"
# Release profile: scripts/test.sh has just built it, so this reuses its artifacts.
build_test() { # package test-name -> path of the test executable
  cargo test --release -p "$1" --test "$2" --no-run --message-format=json 2>/dev/null |
    grep -o "\"executable\":\"[^\"]*/$2-[0-9a-f]*\"" | tail -n 1 | sed 's/^"executable":"//; s/"$//'
}
bins=()
for spec in forcecell-sim:ati_vcan forcecell:ati_cli_vcan; do
  bin=$(build_test "${spec%%:*}" "${spec#*:}") || true
  if [ -z "$bin" ] || [ ! -x "$bin" ]; then
    cargo test --release -p "${spec%%:*}" --test "${spec#*:}" --no-run >&2 || true
    die "could not build the ${spec#*:} test binary (see the errors above)"
  fi
  bins+=("$bin")
done
test_args=(--ignored --test-threads=1)

# ---- native ----------------------------------------------------------------------------------
native_ready() {
  ip link show vcan0 >/dev/null 2>&1 && return 0
  [ "$(id -u)" -eq 0 ] || return 1
  modprobe vcan 2>/dev/null || true
  ip link add dev vcan0 type vcan 2>/dev/null && ip link set vcan0 up 2>/dev/null
}

if [ "$mode" != uml ] && native_ready; then
  echo "vcan-tests: running natively on vcan0"
  ip link set vcan0 up 2>/dev/null || true
  failed=0
  for bin in "${bins[@]}"; do
    FORCECELL_VCAN=vcan0 "$bin" "${test_args[@]}" || failed=1
  done
  [ "$failed" = 0 ] || die "vcan tests failed (natively on vcan0)"
  echo "vcan-tests: all vcan tests passed natively on vcan0"
  exit 0
fi
[ "$mode" = native ] && die "FORCECELL_VCAN_MODE=native but this kernel has no usable vcan0 (modprobe vcan failed)"

# ---- User-Mode Linux -------------------------------------------------------------------------
uml=$(command -v linux.uml) || die "linux.uml not found (apt-get install user-mode-linux)"
work=$(mktemp -d "$root/target/vcan-uml.XXXXXX")
trap '[ -n "${KEEP_UML:-}" ] || rm -rf "$work"' EXIT
status_file=$work/status
output_file=$work/output
init=$work/init.sh

cat >"$init" <<EOF
#!/bin/sh
# PID 1 of the UML guest: load CAN, create vcan0, run the tests, write the status to the host, halt.
PATH=/sbin:/usr/sbin:/bin:/usr/bin
export PATH
fail() { echo "\$*" >"$output_file"; echo 97 >"$status_file"; sync; halt -f; }
mount -t proc proc /proc || fail "guest: cannot mount /proc"
mount -t sysfs sysfs /sys 2>/dev/null
m=/usr/lib/uml/modules/\$(uname -r)
[ -d "\$m" ] || fail "guest: no modules for kernel \$(uname -r) under /usr/lib/uml/modules"
for k in kernel/net/can/can.ko kernel/net/can/can-raw.ko kernel/drivers/net/can/dev/can-dev.ko kernel/drivers/net/can/vcan.ko; do
  insmod "\$m/\$k" || fail "guest: insmod \$k failed"
done
ip link set lo up
ip link add dev vcan0 type vcan && ip link set vcan0 up || fail "guest: cannot create vcan0"
cd "$root"
status=0
for bin in ${bins[*]}; do
  FORCECELL_VCAN=vcan0 RUST_BACKTRACE=1 "\$bin" ${test_args[*]} >>"$output_file" 2>&1 || status=1
done
echo \$status >"$status_file"
sync
halt -f
EOF
chmod +x "$init"

echo "vcan-tests: no usable vcan on this kernel; running inside User-Mode Linux"
timeout 900 "$uml" mem=512M root=/dev/root rootfstype=hostfs rootflags=/ rw init="$init" \
  con=null con0=null,fd:1 </dev/null >"$work/console.log" 2>&1 || true

[ -f "$output_file" ] && cat "$output_file"
if [ ! -s "$status_file" ]; then
  tail -n 40 "$work/console.log" >&2 || true
  die "the UML guest wrote no status (it did not boot or did not finish): see the console log above"
fi
status=$(cat "$status_file")
[ "$status" = 0 ] || die "vcan tests failed inside UML (exit status $status)"
echo "vcan-tests: all vcan tests passed inside UML"

#!/usr/bin/env bash
# Runs the ATI CAN driver's integration tests on a real SocketCAN interface (vcan0). It picks the first
# of these that works on this machine, and says which it picked and why:
#   1. native  - this kernel has CAN (a developer's Linux box): vcan0 on the host;
#   2. uml     - User-Mode Linux (docs/testing.md), only after a short boot probe shows that
#                its init runs (it cannot on a CPU with AMX: "ptrace set fp regs failed");
#   3. qemu    - Debian's own kernel under QEMU's software emulation (docs/testing.md), the
#                host's root filesystem shared over virtio-9p. The kernel is unpacked from its .deb into
#                target/vcan-qemu/ (never installed into /boot) and the initramfs is built there from
#                busybox-static, both cached. KVM is not used: /dev/kvm exists on the build machines but
#                hangs there, and software emulation needs no probe.
# The test binaries are built on the host and run unchanged in the guest, which sees the host's files.
#
# Usage: scripts/vcan-tests.sh                         (auto: native, else UML, else QEMU)
#        FORCECELL_VCAN_FILTER=replay scripts/vcan-tests.sh   (only the tests whose names contain it)
#        FORCECELL_VCAN_MODE=native|uml|qemu scripts/vcan-tests.sh   (force one; fails if it cannot run)
#        FORCECELL_VCAN_STALL=60/300 scripts/vcan-tests.sh   (UML: the guest gets 60 ms of CPU in every
#                                                            300 ms, a host that stalls it up to 240 ms)
# Prerequisites are installed with apt-get when missing. Exits non-zero, with the guest's output, when a
# prerequisite is missing, the guest does not boot or finish, or any test fails. Never a silent skip.
set -euo pipefail

cd "$(dirname "$0")/.."
root=$PWD
mode=${FORCECELL_VCAN_MODE:-auto}
case "$mode" in auto | native | uml | qemu) ;; *)
  echo "vcan-tests: FORCECELL_VCAN_MODE must be native, uml or qemu (or unset for auto), not '$mode'" >&2
  exit 2
  ;;
esac
started=$SECONDS

die() {
  echo "vcan-tests: $*" >&2
  exit 1
}
say() { echo "vcan-tests: $*"; }

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
    die "need root for: $* (run as root or install sudo)"
  fi
}

apt_updated=0
apt_update() {
  [ "$apt_updated" = 1 ] && return 0
  as_root apt-get update -qq || die "apt-get update failed"
  apt_updated=1
}

# install PACKAGE... : installs the Debian packages that are not installed yet.
install() {
  local missing=() p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
  done
  ((${#missing[@]})) || return 0
  command -v apt-get >/dev/null || die "missing ${missing[*]} and no apt-get to install them"
  say "installing ${missing[*]}"
  apt_update
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" \
    >/dev/null || die "apt-get install ${missing[*]} failed"
}

install can-utils iproute2 kmod

# ---- build on the host -----------------------------------------------------------------------
# The driver-vs-node scenarios and can-utils interop (sim/tests/ati_vcan.rs) and the CLI's ATI commands
# (tests/ati_cli_vcan.rs). Their vcan tests are #[ignore]d in a plain `cargo test`.
say "building the test binaries"
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
# FORCECELL_VCAN_FILTER=NAME runs only the vcan tests whose names contain NAME (a subset, e.g. replay).
test_args=(--ignored --test-threads=1 ${FORCECELL_VCAN_FILTER:-})

mkdir -p "$root/target"
work=$(mktemp -d "$root/target/vcan-run.XXXXXX")
trap '[ -n "${KEEP_VCAN_WORK:-}" ] || rm -rf "$work"' EXIT
status_file=$work/status
output_file=$work/output

# The guest's test run, written for a POSIX shell with the host's tools on PATH. $1: what to run before
# the tests (load the CAN modules), $2: the deadline scale for the tests, $3: how to power off.
write_guest_tests() {
  cat <<EOF
PATH=/sbin:/usr/sbin:/bin:/usr/bin
export PATH
fail() { echo "\$*" >>"$output_file"; echo 97 >"$status_file"; sync; $3; }
$1
ip link set lo up
ip link add dev vcan0 type vcan && ip link set vcan0 up || fail "guest: cannot create vcan0"
cd "$root"
status=0
for bin in ${bins[*]}; do
  FORCECELL_VCAN=vcan0 FORCECELL_VCAN_TIME_SCALE=$2 RUST_BACKTRACE=1 "\$bin" ${test_args[*]} >>"$output_file" 2>&1 || status=1
done
echo \$status >"$status_file"
sync
$3
EOF
}

# Reads the status the guest wrote; fails with its output (and the console's tail) otherwise.
finish() { # where console-log
  local where=$1 console=$2
  [ -f "$output_file" ] && cat "$output_file"
  if [ ! -s "$status_file" ]; then
    echo "---- last lines of the $where console ----" >&2
    tail -n 40 "$console" >&2 || true
    die "the $where guest wrote no status (it did not boot or did not finish): see its console above"
  fi
  local status
  status=$(cat "$status_file")
  [ "$status" = 0 ] || die "vcan tests failed inside $where (exit status $status)"
  # A pass must have run tests: each binary prints 'test result: ok. N passed'.
  local ran
  ran=$(grep -o 'test result: ok\. [0-9]* passed' "$output_file" | awk '{s += $4} END {print s + 0}')
  [ "$ran" -gt 0 ] || die "the $where guest reported success but no test ran"
  say "all $ran vcan tests passed inside $where ($((SECONDS - started)) s)"
}

# ---- 1. native -------------------------------------------------------------------------------
native_ready() {
  ip link show vcan0 >/dev/null 2>&1 && return 0
  [ "$(id -u)" -eq 0 ] || return 1
  modprobe vcan 2>/dev/null || true
  ip link add dev vcan0 type vcan 2>/dev/null && ip link set vcan0 up 2>/dev/null
}

if [ "$mode" = auto ] || [ "$mode" = native ]; then
  if native_ready; then
    say "mode native: this kernel has CAN; running on the host's vcan0"
    ip link set vcan0 up 2>/dev/null || true
    failed=0
    for bin in "${bins[@]}"; do
      FORCECELL_VCAN=vcan0 "$bin" "${test_args[@]}" || failed=1
    done
    [ "$failed" = 0 ] || die "vcan tests failed (natively on vcan0)"
    say "all vcan tests passed natively on vcan0 ($((SECONDS - started)) s)"
    exit 0
  fi
  [ "$mode" = native ] && die "FORCECELL_VCAN_MODE=native but this kernel has no usable vcan0 (modprobe vcan failed; run as root on a kernel with CONFIG_CAN_VCAN)"
  say "native vcan: not available (this kernel has no CAN support)"
fi

# ---- 2. User-Mode Linux ----------------------------------------------------------------------
uml_run() { # init-script console-log timeout-seconds
  timeout "$3" linux.uml mem=512M root=/dev/root rootfstype=hostfs rootflags=/ rw init="$1" \
    con=null con0=null,fd:1 </dev/null >"$2" 2>&1 || true
}

uml_boots() {
  local probe=$work/uml-probe.sh mark=$work/uml-probe.ok
  printf '#!/bin/sh\necho ok >%s\nsync\nhalt -f\n' "$mark" >"$probe"
  chmod +x "$probe"
  uml_run "$probe" "$work/uml-probe.log" 60
  [ -s "$mark" ]
}

if [ "$mode" = auto ] || [ "$mode" = uml ]; then
  install user-mode-linux
  if uml_boots; then
    # The guest has one CPU and stalls when its host is slow: a CI host showed 140-150 ms with nothing
    # else running, which a 20 ms sensor turnaround and a 100 ms robot watchdog took for faults.
    # Every wall-clock bound of the tests gets twenty times its native headroom (tests/ati_cli_vcan.rs,
    # sim/tests/ati_vcan.rs). Checked with the guest in a CPU cgroup: given 60 ms of every 300 ms
    # (stalls up to 240 ms) all pass at 20; at 10 run's start-up tare fails (its 200 ms turnaround).
    say "mode uml: User-Mode Linux boots here (probe passed); running inside it (time scale ${FORCECELL_VCAN_TIME_SCALE:-20})"
    init=$work/init.sh
    {
      echo '#!/bin/sh'
      echo '# PID 1 of the UML guest: load CAN, create vcan0, run the tests, write the status to the host, halt.'
      write_guest_tests "$(
        cat <<'EOF'
mount -t proc proc /proc || fail "guest: cannot mount /proc"
mount -t sysfs sysfs /sys 2>/dev/null
m=/usr/lib/uml/modules/$(uname -r)
[ -d "$m" ] || fail "guest: no modules for kernel $(uname -r) under /usr/lib/uml/modules"
for k in kernel/net/can/can.ko kernel/net/can/can-raw.ko kernel/drivers/net/can/dev/can-dev.ko kernel/drivers/net/can/vcan.ko; do
  insmod "$m/$k" || fail "guest: insmod $k failed"
done
EOF
      )" "${FORCECELL_VCAN_TIME_SCALE:-20}" "halt -f"
    } >"$init"
    chmod +x "$init"
    if [ -n "${FORCECELL_VCAN_STALL:-}" ]; then
      # A stalling host on demand: the guest gets QUOTA ms of CPU in every PERIOD ms (a CPU cgroup),
      # so it stalls up to PERIOD - QUOTA ms, as CI's host did.
      [[ "$FORCECELL_VCAN_STALL" =~ ^([0-9]+)/([0-9]+)$ ]] ||
        die "FORCECELL_VCAN_STALL must be QUOTA/PERIOD in ms (e.g. 60/300), not '$FORCECELL_VCAN_STALL'"
      quota=$((BASH_REMATCH[1] * 1000)) period=$((BASH_REMATCH[2] * 1000))
      if [ -d /sys/fs/cgroup/cpu ] && [ -f /sys/fs/cgroup/cpu/cgroup.procs ]; then
        cg=/sys/fs/cgroup/cpu/forcecell-vcan-stall
        as_root mkdir -p "$cg"
        echo "$period" | as_root tee "$cg/cpu.cfs_period_us" >/dev/null
        echo "$quota" | as_root tee "$cg/cpu.cfs_quota_us" >/dev/null
      elif [ -f /sys/fs/cgroup/cgroup.controllers ]; then
        cg=/sys/fs/cgroup/forcecell-vcan-stall
        as_root mkdir -p "$cg"
        echo "$quota $period" | as_root tee "$cg/cpu.max" >/dev/null
      else
        die "FORCECELL_VCAN_STALL needs a CPU cgroup (v1 cpu or v2), and this machine has none"
      fi
      say "stalling the guest: $((quota / 1000)) ms of CPU in every $((period / 1000)) ms ($cg)"
      (
        me=$BASHPID # this subshell (a pipeline's $BASHPID would be the pipeline's own)
        echo "$me" | as_root tee "$cg/cgroup.procs" >/dev/null || die "cannot move the guest into $cg"
        uml_run "$init" "$work/console.log" 1800
      )
    else
      uml_run "$init" "$work/console.log" 900
    fi
    finish UML "$work/console.log"
    exit 0
  fi
  reason="its init did not run within 60 s"
  grep -q 'ptrace set fp regs failed' "$work/uml-probe.log" 2>/dev/null &&
    reason="it panics before init ('ptrace set fp regs failed': this CPU's XSAVE area, e.g. AMX, is too large for it)"
  if [ "$mode" = uml ]; then
    tail -n 20 "$work/uml-probe.log" >&2 || true
    die "FORCECELL_VCAN_MODE=uml but User-Mode Linux cannot boot here: $reason"
  fi
  say "User-Mode Linux: not usable here, $reason"
fi

# ---- 3. QEMU (software emulation) ------------------------------------------------------------
install qemu-system-x86 busybox-static cpio
cache=$root/target/vcan-qemu
mkdir -p "$cache"

# The kernel: the version linux-image-amd64 names, downloaded as a .deb and unpacked into the cache.
kpkg=$(apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-[0-9]/ {print $2; exit}')
if [ -z "$kpkg" ]; then
  apt_update
  kpkg=$(apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-[0-9]/ {print $2; exit}')
fi
[ -n "$kpkg" ] || die "apt-cache cannot name the Debian kernel package (linux-image-amd64 has no linux-image-* dependency)"
kdir=$cache/$kpkg
if [ ! -f "$kdir/.unpacked" ]; then
  say "fetching the kernel $kpkg with apt-get download (unpacked into $kdir, not installed)"
  rm -rf "$kdir" "$cache"/dl && mkdir -p "$cache/dl"
  (cd "$cache/dl" && apt-get download "$kpkg" >/dev/null 2>&1) ||
    { apt_update && (cd "$cache/dl" && apt-get download "$kpkg" >/dev/null); } ||
    die "apt-get download $kpkg failed"
  dpkg-deb -x "$cache"/dl/"$kpkg"_*.deb "$kdir" || die "dpkg-deb could not unpack $kpkg"
  rm -rf "$cache/dl"
  touch "$kdir/.unpacked"
fi
vmlinuz=$(ls "$kdir"/boot/vmlinuz-* 2>/dev/null | head -n 1)
[ -n "$vmlinuz" ] || die "no vmlinuz in $kpkg"
kver=${vmlinuz##*/vmlinuz-}
moddir=$kdir/lib/modules/$kver

# modules_in_order NAME... : the module files for NAMEs, each after its dependencies (modinfo -F depends);
# a module with no file is built into the kernel and skipped.
declare -A seen=()
ordered=()
add_module() {
  local name=${1//-/_} file dep
  [ -n "${seen[$name]:-}" ] && return 0
  seen[$name]=1
  file=$(find "$moddir/kernel" \( -name "$name.ko*" -o -name "${name//_/-}.ko*" \) -print -quit)
  [ -n "$file" ] || return 0
  for dep in $(modinfo -F depends "$file" | tr ',' ' '); do add_module "$dep"; done
  ordered+=("$file")
}

# A module as a plain .ko (busybox insmod in the initramfs reads no compressed modules).
plain_ko() { # file dest-dir -> path of the plain .ko
  local f=$1 out=$2/$(basename "${1%.xz}")
  out=${out%.zst}
  case "$f" in
  *.ko.xz) xz -dc "$f" >"$out" ;;
  *.ko.zst) zstd -qdc "$f" >"$out" ;;
  *) cp "$f" "$out" ;;
  esac
  echo "$out"
}

initrd=$cache/initrd-$kver.gz
if [ ! -s "$initrd" ]; then
  say "building the initramfs (busybox-static + virtio/9p modules) in $cache"
  ir=$work/initramfs
  mkdir -p "$ir/bin" "$ir/mod" "$ir/proc" "$ir/dev" "$ir/host"
  cp /bin/busybox "$ir/bin/busybox"
  ordered=()
  for m in virtio_pci 9pnet_virtio 9p; do add_module "$m"; done
  : >"$ir/mod/order"
  for f in "${ordered[@]}"; do basename "$(plain_ko "$f" "$ir/mod")" >>"$ir/mod/order"; done
  cat >"$ir/init" <<'EOF'
#!/bin/busybox sh
# PID 1 of the initramfs: mount the host's root over virtio-9p and hand over to the test script in it.
b=/bin/busybox
off() { $b echo 1 >/proc/sys/kernel/sysrq; $b echo o >/proc/sysrq-trigger; $b sleep 30; }
$b mount -t proc proc /proc
$b mount -t devtmpfs dev /dev
for m in $($b cat /mod/order); do $b insmod /mod/$m || $b echo "initramfs: insmod $m failed"; done
$b mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 hostroot /host || { $b echo "initramfs: cannot mount the host's root over 9p"; off; }
$b mount --move /dev /host/dev
$b mount --move /proc /host/proc
exec $b chroot /host /bin/sh -c "$guest_init"
EOF
  chmod +x "$ir/init"
  (cd "$ir" && find . | cpio -o -H newc --quiet | gzip -1) >"$initrd.tmp" && mv "$initrd.tmp" "$initrd"
fi

# The CAN modules, loaded by the guest (with the host's insmod) from the unpacked kernel.
candir=$cache/can-$kver
if [ ! -f "$candir/order" ]; then
  rm -rf "$candir" && mkdir -p "$candir"
  ordered=()
  seen=()
  for m in can can_raw can_dev vcan; do add_module "$m"; done
  for f in "${ordered[@]}"; do plain_ko "$f" "$candir" >>"$candir/order"; done
fi

guest=$work/guest.sh
{
  echo '#!/bin/sh'
  echo '# Runs inside the QEMU guest, chrooted into the host filesystem: load CAN, create vcan0, run the tests.'
  write_guest_tests "$(
    cat <<EOF
mount -t sysfs sysfs /sys 2>/dev/null
mount -t tmpfs tmpfs /dev/shm 2>/dev/null
for k in \$(cat "$candir/order"); do insmod "\$k" || fail "guest: insmod \$k failed"; done
EOF
  )" "${FORCECELL_VCAN_TIME_SCALE:-4}" 'echo 1 >/proc/sys/kernel/sysrq; echo o >/proc/sysrq-trigger; sleep 30'
} >"$guest"
chmod +x "$guest"

say "mode qemu: Debian kernel $kver under QEMU software emulation (TCG), host root over virtio-9p"
timeout 1800 qemu-system-x86_64 -accel tcg,thread=multi -cpu max -m 2048 -smp 2 -nographic -no-reboot \
  -kernel "$vmlinuz" -initrd "$initrd" \
  -append "console=ttyS0 quiet panic=-1 guest_init=$guest" \
  -virtfs local,path=/,mount_tag=hostroot,security_model=passthrough,id=hostroot,multidevs=remap \
  </dev/null >"$work/console.log" 2>&1 || true
finish QEMU "$work/console.log"

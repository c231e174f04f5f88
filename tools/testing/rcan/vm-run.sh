#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
#
# Run a command inside a throw-away QEMU VM booted with the rcan test kernel.
#
#   vm-run.sh [--kernel BZIMAGE] [--timeout SECONDS] [--mem MB] [--smp N]
#             [--out DIR] [--qemu-extra 'ARGS'] [--append 'PARAMS']
#             -- COMMAND [ARGS...]
#   vm-run.sh --scan FILE...
#
# The guest sees the host's root filesystem read-only (9p) on a writable
# tmpfs /, so host-built binaries, bash, kmod, iproute2 and can-utils run
# unchanged, and any host path resolves to the same path in the guest --
# except below /tmp, /run, /var/tmp, /dev, /proc and /sys, which are the
# guest's own (fresh tmpfs etc.); the host's files there are at
# /rcan-host/PATH. COMMAND runs as root in $RCAN_ROOT with stdin from
# /dev/null, RCAN_* variables forwarded, RCAN_GUEST=1 and RCAN_OUT=/rcan-out:
# the --out directory (default: a new mktemp directory), shared read-write
# and also mounted at its host path.
#
# COMMAND's output appears on stdout as it runs (serial console, with kernel
# messages of level WARNING and worse interleaved) and is saved in
# OUT/console.log; the full kernel log ends up in OUT/dmesg.txt and, on
# kmemleak kernels, the leak report in OUT/kmemleak.txt (the release
# kernel has kmemleak built in but off unless the command line says
# kmemleak=on: --append 'kmemleak=on'). --append adds PARAMS to the
# kernel command line.
#
# Exit status:
#   the command's own status if the VM ran cleanly, else
#   124  the VM timed out (--timeout, default 600 s)
#   125  the guest crashed, panicked or its init failed (no OUT/rc)
#   126  the kernel reported a problem (oops, WARNING, KASAN, lockdep,
#        kmemleak, ...) during the run; the reports are printed
#   1    usage or setup error (missing kernel, qemu failed to start, ...)
# --scan only scans the given kernel logs: 126 if they hold a report, else 0.
#
# Environment: RCAN_KERNEL (release|debug) picks the default kernel and
# memory size; RCAN_KVM=auto|0|1|icount (default auto) picks the accelerator:
# auto probes once whether KVM guests actually boot here (nested KVM often
# hangs) and caches the verdict, falling back to TCG; icount is
# single-threaded TCG with instruction counting (the guest clock advances
# 1 ns per guest instruction and skips idle time), so CPU time measured in
# the guest counts instructions whatever the host's load: for benchmarks
# on a shared host (Documentation/networking/rcan/benchmarks.rst), never
# for the test suite (much slower).
set -euo pipefail
# shellcheck source=lib.sh source-path=SCRIPTDIR
. "$(dirname "$0")/lib.sh"

VM_DIR="$RCAN_ROOT/tools/testing/rcan/vm"
QEMU=qemu-system-x86_64

usage() {
	sed -n '6,10s/^# \{0,1\}//p' "$0" >&2
	exit 1
}

# --- kernel log scanner ------------------------------------------------------

# Kernel problem reports, as extended regexps matched anywhere in a line.
SCAN_PATTERNS=(
	'Oops'
	'BUG:'                         # incl. soft lockup, KASAN, sleeping in atomic
	'WARNING:'                     # WARN_ON and lockdep headers
	'KASAN'
	'UBSAN'
	'kernel BUG'
	'general protection fault'
	'Call Trace:'
	'Kernel panic'
	'panicked at'                  # Rust panic!() in kernel code
	'possible recursive locking'
	'possible circular locking'
	'inconsistent lock state'
	'suspicious RCU usage'
	'unreferenced object'          # kmemleak
	'INFO: task .* blocked'
	'watchdog: BUG: soft lockup'
	'rcu_preempt detected stalls'
	'rcu: INFO:'
	'detected stalls on CPU'
	'refcount_t:'
	'list_add corruption'
	'list_del corruption'
)
# Lines that match a pattern above but are not problems. Each entry must say
# why it is benign and where it was seen.
SCAN_EXCLUDES=(
)

# scan_log FILE...: print every report with context; return 1 if any.
scan_log() {
	local re ex f found=0
	re=$(IFS='|'; echo "${SCAN_PATTERNS[*]}")
	ex=$(IFS='|'; echo "${SCAN_EXCLUDES[*]-}")
	for f in "$@"; do
		[ -s "$f" ] || continue
		# Two passes over the file: collect hits, then print 5 lines
		# before and 20 after each (hits marked with ">>"), at most 400.
		if ! awk -v re="$re" -v ex="$ex" -v name="$f" '
			NR == FNR {
				if ($0 ~ re && (ex == "" || $0 !~ ex)) {
					hits++
					for (i = FNR - 5; i <= FNR + 20; i++) show[i] = 1
					hit[FNR] = 1
				}
				next
			}
			FNR == 1 {
				if (!hits) exit 0
				printf "rcan: kernel problem report(s) in %s:\n", name
			}
			show[FNR] {
				if (printed && FNR != last + 1) print "--"
				if (++printed > 400) { print "[...]"; exit 1 }
				printf "%s %s\n", hit[FNR] ? ">>" : "  ", $0
				last = FNR
			}
			END { exit hits ? 1 : 0 }
		' "$f" "$f"; then
			found=1
		fi
	done
	return $found
}

# --- initramfs -----------------------------------------------------------------

# busybox applets the init script uses.
APPLETS="sh mount mkdir cat chroot poweroff reboot dmesg sleep sync ln readlink hostname ip"

# Build (once) the initramfs: /init and a static busybox. Prints its path.
build_initramfs() {
	local bb init hash img tmp a
	bb=$(command -v busybox) || die "busybox not found (apt-get install busybox-static)"
	bb=$(readlink -f "$bb")
	init="$VM_DIR/init"
	if command -v readelf >/dev/null && readelf -d "$bb" 2>/dev/null | grep -q NEEDED; then
		die "$bb is dynamically linked; the initramfs needs busybox-static"
	fi
	hash=$({ cat "$init" "$bb"; echo "$APPLETS"; } | sha256sum | cut -c1-12)
	img="$RCAN_CACHE/initramfs-$hash.cpio"
	if [ ! -s "$img" ]; then
		mkdir -p "$RCAN_CACHE"
		tmp=$(mktemp -d)
		mkdir -p "$tmp/bin" "$tmp/dev" "$tmp/proc" "$tmp/sys"
		cp "$bb" "$tmp/bin/busybox"
		for a in $APPLETS; do ln -s busybox "$tmp/bin/$a"; done
		install -m 0755 "$init" "$tmp/init"
		# Temp name + mv: concurrent runs never see a partial archive.
		(cd "$tmp" && find . | LC_ALL=C sort | cpio -o -H newc -R 0:0 --quiet) \
			>"$img.$$"
		mv "$img.$$" "$img"
		rm -rf "$tmp"
	fi
	echo "$img"
}

# --- accelerator ---------------------------------------------------------------

kvm_usable() { [ -c /dev/kvm ] && [ -r /dev/kvm ] && [ -w /dev/kvm ]; }

# Boot the kernel once under KVM; succeed if init reports in within 30 s.
# Nested KVM on some CI hosts hangs right after the BIOS, hence the
# timeout with SIGKILL.
kvm_probe() {
	local kernel=$1 initrd=$2 log ok=1
	log=$(mktemp)
	timeout -s KILL 30 "$QEMU" -nodefaults -no-user-config -display none \
		-accel kvm -cpu host -m 256 -smp 1 -no-reboot \
		-kernel "$kernel" -initrd "$initrd" \
		-append "console=ttyS0 rdinit=/init panic=-1 quiet rcan.kvmprobe" \
		-serial "file:$log" </dev/null >/dev/null 2>&1 || true
	grep -q RCAN-KVM-PROBE-OK "$log" && ok=0
	rm -f "$log"
	return $ok
}

# Sets the array accel to the qemu accelerator arguments to use.
pick_accel() {
	local kernel=$1 initrd=$2 key file verdict=
	case ${RCAN_KVM:-auto} in
	0) verdict=tcg ;;
	icount) verdict=icount ;;
	1) kvm_usable || die "RCAN_KVM=1 but /dev/kvm is not usable"; verdict=kvm ;;
	auto)
		if kvm_usable; then
			# The verdict depends on the host kernel and qemu.
			key="$(uname -r) $("$QEMU" --version | head -n 1)"
			file="$RCAN_CACHE/kvm-verdict"
			if [ -f "$file" ] && [ "$(head -n 1 "$file")" = "$key" ]; then
				verdict=$(sed -n 2p "$file")
			fi
			if [ "$verdict" != kvm ] && [ "$verdict" != tcg ]; then
				log "probing whether KVM guests work here (once, up to 30 s)"
				if kvm_probe "$kernel" "$initrd"; then verdict=kvm; else verdict=tcg; fi
				log "KVM verdict: $verdict (cached in $file)"
				mkdir -p "$RCAN_CACHE"
				printf '%s\n%s\n' "$key" "$verdict" >"$file.$$"
				mv "$file.$$" "$file"
			fi
		else
			verdict=tcg
		fi
		;;
	*) die "RCAN_KVM must be auto, 0, 1 or icount" ;;
	esac
	if [ "$verdict" = kvm ]; then
		accel=(-accel kvm -cpu host)
	elif [ "$verdict" = icount ]; then
		accel=(-accel "tcg,thread=single" -icount "shift=0,sleep=off" -cpu max)
	else
		# Multi-threaded TCG: one host thread per vCPU.
		accel=(-accel "tcg,thread=multi" -cpu max)
		tcg_tsc_khz=$(host_tsc_khz)
	fi
}

# The host's TSC frequency in kHz, printed only when the host's kernel
# knows it rather than measured it (CPU flag tsc_known_freq: from CPUID or
# the hypervisor) and no cpufreq driver scales the CPUs, so that /proc/cpuinfo's
# "cpu MHz" is that known frequency (cpu_khz), the same on every CPU.
# Prints nothing otherwise.
#
# Why: under multi-threaded TCG the guest's TSC is the host's (QEMU reads
# the host's TSC), and the guest calibrates it at boot against the
# emulated PIT and HPET in loops of a few milliseconds. When the host is
# loaded, the vCPU thread is descheduled inside those loops and the
# calibration comes out wrong: "tsc: PIT calibration deviates from HPET:
# 194272 2592796", then "Detected 194.272 MHz processor" (the truth was
# 2593), in a debug boot beside make soak at host load average 11
# (2026-11-29). The refined calibration a second later disagreed by more
# than 1 % and was thrown away, so the guest's clock ran 13 times too fast
# for the next 100 s, until the clocksource watchdog switched to the HPET;
# timers fired 13 times early and the RCU stall detector reported
# "rcu_preempt kthread timer wakeup didn't happen for 24050 jiffies"
# before any module was loaded, failing the VM. tsc_early_khz= skips that
# calibration; the refined one (against the HPET over a second, robust to
# descheduling) still runs and corrects the value within 1 %, and the
# clocksource watchdog still checks the TSC against the HPET.
host_tsc_khz() {
	grep -qw tsc_known_freq /proc/cpuinfo || return 0
	[ ! -e /sys/devices/system/cpu/cpu0/cpufreq ] || return 0
	awk -F': *' '/^cpu MHz/ { f[$2] = 1; n++ }
		END {
			k = 0
			for (v in f) { k++; mhz = v }
			if (n > 0 && k == 1 && mhz + 0 >= 100) printf "%d\n", mhz * 1000 + 0.5
		}' /proc/cpuinfo
}

# --- main ----------------------------------------------------------------------

kernel='' timeout=600 mem='' smp=2 out='' qemu_extra='' append=''
[ $# -gt 0 ] || usage
while [ $# -gt 0 ]; do
	case $1 in
	--kernel) kernel=${2:?}; shift 2 ;;
	--timeout) timeout=${2:?}; shift 2 ;;
	--mem) mem=${2:?}; shift 2 ;;
	--smp) smp=${2:?}; shift 2 ;;
	--out) out=${2:?}; shift 2 ;;
	--qemu-extra) qemu_extra=${2?}; shift 2 ;;
	--append) append=${2?}; shift 2 ;;
	--scan)
		shift
		[ $# -gt 0 ] || usage
		scan_log "$@" && exit 0
		exit 126
		;;
	--) shift; break ;;
	-h | --help) usage ;;
	*) usage ;;
	esac
done
[ $# -gt 0 ] || usage
[[ $timeout =~ ^[1-9][0-9]*$ ]] || die "--timeout wants seconds"
[[ $smp =~ ^[1-9][0-9]*$ ]] || die "--smp wants a number of CPUs"
[[ -z $mem || $mem =~ ^[1-9][0-9]*$ ]] || die "--mem wants MiB"
if [ -z "$mem" ]; then
	# KASAN's shadow memory and lockdep want more room.
	if [ "$RCAN_KERNEL" = debug ]; then mem=2048; else mem=1024; fi
fi

if [ -z "$kernel" ]; then
	kernel="$(rcan_kbuild)/arch/x86/boot/bzImage"
	[ -f "$kernel" ] || die "no $RCAN_KERNEL kernel at $kernel; run tools/testing/rcan/build-kernel.sh first"
fi
[ -f "$kernel" ] || die "kernel $kernel not found"
command -v "$QEMU" >/dev/null || die "$QEMU not found (apt-get install qemu-system-x86)"

if [ -z "$out" ]; then
	out=$(mktemp -d "${TMPDIR:-/tmp}/rcan-vm.XXXXXX")
else
	mkdir -p "$out"
fi
out=$(cd "$out" && pwd -P)
# Results of an earlier run in the same directory must not be mistaken
# for this one's.
rm -f "$out/rc" "$out/dmesg.txt" "$out/kmemleak.txt" "$out/console.log" \
	"$out/init-error" "$out/vm-cmd.sh" "$out/vm-init.conf"

initrd=$(build_initramfs)
pick_accel "$kernel" "$initrd"
read -ra extra <<<"$qemu_extra"

# The command goes through a script in the output share: no kernel
# command line quoting, any argument survives. %q output is for bash,
# which runs the script in the guest.
{
	echo "# generated by vm-run.sh"
	export RCAN_ROOT RCAN_CACHE RCAN_KERNEL
	while IFS= read -r v; do
		printf 'export %s=%q\n' "$v" "${!v}"
	done < <(compgen -e | grep '^RCAN_' | grep -v -x -e RCAN_GUEST -e RCAN_OUT || true)
	printf 'export HOME=%q\n' "$HOME"
	printf 'export PATH=%q\n' "$HOME/.cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
	echo "export TERM=dumb LANG=C.UTF-8 RCAN_GUEST=1 RCAN_OUT=/rcan-out"
	printf 'cd %q || exit 125\n' "$RCAN_ROOT"
	printf 'exec'
	printf ' %q' "$@"
	printf '\n'
} >"$out/vm-cmd.sh"
# Read by the guest's busybox sh: single quotes, ' escaped.
printf "RCAN_HOST_OUT='%s'\n" "${out//\'/\'\\\'\'}" >"$out/vm-init.conf"
printf "RCAN_HOST_ROOT='%s'\n" "${RCAN_ROOT//\'/\'\\\'\'}" >>"$out/vm-init.conf"

# console=ttyS0: the only console. loglevel=5: WARNING and worse still show
# up live, between the command's output; the full log goes to dmesg.txt.
# log_buf_len: room for long lockdep/KASAN reports (tinyconfig: 128 KiB).
# panic=-1 + -no-reboot: a panic ends qemu at once instead of hanging.
# no5lvl: 4-level paging even where the CPU model has LA57 (TCG's -cpu max
# has it). With 5-level paging, 6.12's identify_cpu() clears the boot CPU's
# feature bits and reads them again; pgtable_l5_enabled() reads X86_FEATURE_LA57,
# so an interrupt taken in that window computes 4-level KASAN shadow bounds
# for a 5-level address: "BUG: KASAN: wild-memory-access in rcu_is_watching"
# at about 2 s into a debug boot, on roughly one boot in thirty under TCG,
# which failed a whole make check (2026-11-27). Our code is not involved.
#
# The RCU stall detector's threshold (21 s by default; the test kernels
# have no soft-lockup or hung-task detector) is raised to 60 s: under TCG
# a loaded host can deschedule the guest's vCPU threads for tens of
# seconds, and the guest then reports a stall it did not cause
# ("rcu_preempt kthread starved for 12459 jiffies", 74 s into a debug boot
# before any module was loaded, host load average 13, 2026-11-29: the
# whole VM stage failed). A real stall does not end and is still
# reported, 60 s later.
cmdline="console=ttyS0 rdinit=/init panic=-1 loglevel=5 log_buf_len=4M no5lvl"
cmdline+=" rcupdate.rcu_cpu_stall_timeout=60"
# Boot time, which every VM pays (each debug shard about a minute under
# TCG, 2026-11-29, initcall_debug): pty.legacy_count=0 skips the 256
# legacy BSD pty pairs (/dev/ptyXX; nothing here uses them, Unix98 ptys
# stay), 9.5 s of a debug boot in pty_init; and the machine option below,
# acpi-pci-hotplug-with-bridge-support=off, drops the ACPI hotplug methods
# QEMU writes for every PCI slot (no test hotplugs a card), which cut the
# debug kernel's acpi_init from about 18 s to 11.
cmdline+=" pty.legacy_count=0"
# The IO-APIC timer check (timer_irq_works: do jiffies advance during a
# short busy wait?) fails when the host does not run QEMU's timers in
# that window: "Kernel panic - not syncing: IO-APIC + timer doesn't
# work!" at boot (a release guest beside make check's VMs, 2026-11-30).
# QEMU's timer is not one of the broken boards the check is for.
cmdline+=" no_timer_check"
# The TSC's frequency under TCG, when the host knows it: host_tsc_khz.
[ -z "${tcg_tsc_khz:-}" ] || cmdline+=" tsc_early_khz=$tcg_tsc_khz"
[ -z "$append" ] || cmdline+=" $append"

qemu_args=(
	-nodefaults -no-user-config -display none -no-reboot
	-machine q35 "${accel[@]}" -smp "$smp" -m "$mem"
	-global ICH9-LPC.acpi-pci-hotplug-with-bridge-support=off
	-kernel "$kernel" -initrd "$initrd" -append "$cmdline"
	-serial stdio
	-virtfs "local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap"
	-virtfs "local,path=$out,mount_tag=rcanout,security_model=none,multidevs=remap"
	"${extra[@]}"
)

log "booting $kernel (${accel[*]}, $smp CPUs, $mem MiB), output in $out"
# Private scratch: qemu's pid (to stop it if we are killed) and exit status.
run=$(mktemp -d)
trap 'rm -rf "$run"' EXIT
# If this script is interrupted or killed (CI cancel), take the VM along
# instead of leaving it to run until the timeout.
# shellcheck disable=SC2317  # called from the trap below
stop_vm() {
	trap - INT TERM HUP
	[ -s "$run/qemu.pid" ] && kill "$(cat "$run/qemu.pid")" 2>/dev/null
	wait
	log "interrupted; VM stopped"
	exit 130
}
start=$(date +%s)
# stdin from /dev/null: CI has no terminal, and qemu must not put an
# interactive one into raw mode. The serial console ends lines with CRLF;
# strip the CRs for the logs. timeout sends SIGTERM, and SIGKILL 5 s later
# if qemu does not react; --foreground keeps qemu in our process group so
# that ^C reaches it. The pipeline runs in the background because bash
# runs traps only once a foreground job has finished.
{
	qrc=0
	timeout --foreground -k 5 "$timeout" \
		"$QEMU" -pidfile "$run/qemu.pid" "${qemu_args[@]}" </dev/null || qrc=$?
	echo "$qrc" >"$run/qemu.rc"
} | sed -u 's/\r$//' | tee "$out/console.log" &
trap stop_vm INT TERM HUP
wait $! || true
trap - INT TERM HUP
qrc=$(cat "$run/qemu.rc" 2>/dev/null || echo "?")
elapsed=$(($(date +%s) - start))

# 137: qemu ignored SIGTERM and got SIGKILL.
if [ "$qrc" = 124 ] || [ "$qrc" = 137 ]; then
	log "VM timed out after $timeout s"
	exit 124
fi
[ "$qrc" = 0 ] || die "qemu failed (exit $qrc)"
if [ ! -f "$out/rc" ]; then
	if [ -s "$out/init-error" ]; then
		log "guest init failed: $(cat "$out/init-error")"
	else
		log "guest crashed or panicked (no exit status); see $out/console.log"
	fi
	exit 125
fi
rc=$(cat "$out/rc")
log "VM finished in $elapsed s, command exit status $rc"
if ! scan_log "$out/dmesg.txt" "$out/kmemleak.txt"; then
	log "kernel problem reports found (full log: $out/dmesg.txt)"
	exit 126
fi
exit "$rc"

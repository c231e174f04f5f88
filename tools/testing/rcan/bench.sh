#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# The benchmark command (make bench): boot ONE VM on the release test kernel
# and run rcan-bench in it, which measures mainline SocketCAN (can.ko,
# can-raw.ko, vcan echo=1) and our stack (rcan_pf, rcan_can, rcan_raw,
# rcan_loop), one after the other in alternating rounds, with the same
# CAN_RAW programs -- throughput, fan-out cost, latency -- and prints the
# figures, the ratios ours/mainline and a summary table; then (table part)
# the same two stacks with many sockets: bind + close of 1,000 and 10,000
# sockets, the cost of a frame none of them wants, two senders on two
# CPUs, memory per socket; then (dsor part) our DSOR message protocol
# (rcan_dsor over rcan_loop) against mainline ISO-TP (can-isotp over
# vcan): goodput and CPU time per KiB; on request (--part bcm) CAN_BCM:
# kernel CPU per cyclic frame, 1,000 jobs at 10 ms, rcan_bcm against
# can-bcm.ko; on request (--part fd) CAN FD: 64-byte FD frames with BRS
# and classic frames on rcan_loop vs vcan at MTU 72, then a second boot
# with QEMU's CTU CAN FD card (the CTU CAN FD section below); on request
# (--part isotp) CAN_ISOTP: rcan_isotp over rcan_loop against mainline's
# can-isotp.ko over vcan, goodput and CPU per KiB of 4 KiB and 64 KiB
# PDUs (classic and CAN FD) and the frame spacing with STmin 1 ms. Never
# fails on a missed target.
# See Documentation/networking/rcan/benchmarks.rst.
#
#   bench.sh [rcan-bench options]     e.g. --stack mainline, --quick,
#                                     --part table, --part dsor, --part bcm,
#                                     --part fd, --part isotp
#                                     (make bench BENCH_ARGS=...)
#
# Expects the modules and target/release/rcan-bench to be built (make bench
# does that). The summary is saved as bench-summary.txt in the VM output
# directory (RCAN_BENCH_OUT, default a new /tmp/rcan-bench.XXXXXX), next to
# console.log and dmesg.txt.
set -euo pipefail
. "$(dirname "$0")/lib.sh"
cd "$RCAN_ROOT"

if [ "$RCAN_KERNEL" != release ]; then
	log "warning: RCAN_KERNEL=$RCAN_KERNEL: figures from a debug kernel measure its checkers, not the stacks"
fi
[ -x target/release/rcan-bench ] || die "target/release/rcan-bench missing; run make bench (or make userspace)"
# The guest finds mainline's can.ko, can-raw.ko, can-isotp.ko and vcan.ko
# here (vm-run.sh forwards every RCAN_* variable).
RCAN_KBUILD=$(bash "$RCAN_ROOT/tools/testing/rcan/build-kernel.sh")
export RCAN_KBUILD
out=${RCAN_BENCH_OUT:-$(mktemp -d "${TMPDIR:-/tmp}/rcan-bench.XXXXXX")}
mkdir -p "$out"

# The parts asked for (rcan-bench's --part; the last one given counts).
parts=raw,table,dsor
prev=
for a in "$@"; do
	case $a in
	--part=*) parts=${a#--part=} ;;
	*) [ "$prev" = --part ] && parts=$a ;;
	esac
	prev=$a
done
has_part() { case ",${parts// /}," in *",$1,"*) return 0 ;; esac; return 1; }

rc=0
# Both stacks take a few minutes under TCG; the timeout only guards
# against a hang.
bash "$RCAN_ROOT/tools/testing/rcan/vm-run.sh" --timeout 1800 --out "$out" -- \
	target/release/rcan-bench "$@" || rc=$?
if [ -s "$out/bench-summary.txt" ]; then
	log "summary saved in $out/bench-summary.txt"
else
	log "no summary written (see $out/console.log)"
fi

# SJA1000 section (RCAN_BENCH_SJA=0 skips it): a second boot with two QEMU
# kvaser_pci cards on one bus and QEMU's memory-region trace on; in it
# rcan-bench-sja runs mainline sja1000+kvaser_pci and rcan_kvaser_pci in
# alternating rounds, and sja-count.awk counts each driver's register
# accesses in the trace (the same emulator code counts both).
# Not when only the CAN FD and/or ISO-TP parts are asked for.
only_fd_isotp=1
for p in ${parts//,/ }; do
	case $p in fd | isotp) ;; *) only_fd_isotp=0 ;; esac
done
if [ "${RCAN_BENCH_SJA:-1}" != 0 ] && [ "$only_fd_isotp" = 0 ]; then
	[ -x target/release/rcan-bench-sja ] || die "target/release/rcan-bench-sja missing; run make bench (or make userspace)"
	sja="$out/sja1000"
	mkdir -p "$sja"
	log "SJA1000 section: ours vs mainline on two emulated Kvaser PCIcan cards"
	src=0
	# shellcheck disable=SC2086
	bash "$RCAN_ROOT/tools/testing/rcan/vm-run.sh" --timeout 1800 --out "$sja" \
		--qemu-extra "-object can-bus,id=bus0 -device kvaser_pci,canbus=bus0 -device kvaser_pci,canbus=bus0 -trace memory_region_ops_read -trace memory_region_ops_write -D $sja/trace.log" \
		-- target/release/rcan-bench-sja ${RCAN_BENCH_SJA_ARGS:---frames 4000 --rounds 3} |
		tee "$sja/phases.txt" || src=$?
	if grep -q '^SJA-PHASE' "$sja/phases.txt" 2>/dev/null; then
		awk -f "$RCAN_ROOT/tools/testing/rcan/bench/sja-count.awk" "$sja/phases.txt" "$sja/trace.log" |
			tee "$sja/summary.txt"
		log "SJA1000 summary saved in $sja/summary.txt"
		# The trace is large (tens of MB per thousand frames).
		rm -f "$sja/trace.log"
	else
		log "SJA1000 section produced no phases (see $sja/console.log)"
	fi
	[ "$src" = 0 ] || rc=$src
fi

# CTU CAN FD section (with --part fd; RCAN_BENCH_CTU=0 skips it): a boot
# with QEMU's ctucan_pci card (two cores on one bus, as RCAN_QEMU_CAN has
# it for the VM tests) and the memory-region trace on; rcan-bench-ctu runs
# mainline ctucanfd+ctucanfd_pci and rcan_ctucanfd_pci in alternating
# rounds, FD 64-byte and classic 8-byte phases, and sja-count.awk counts
# each driver's register accesses per frame in the trace.
if has_part fd && [ "${RCAN_BENCH_CTU:-1}" != 0 ]; then
	[ -x target/release/rcan-bench-ctu ] || die "target/release/rcan-bench-ctu missing; run make bench (or make userspace)"
	ctu="$out/ctucanfd"
	mkdir -p "$ctu"
	log "CTU CAN FD section: ours vs mainline ctucanfd on QEMU's ctucan_pci card"
	crc=0
	# shellcheck disable=SC2086
	bash "$RCAN_ROOT/tools/testing/rcan/vm-run.sh" --timeout 1800 --out "$ctu" \
		--qemu-extra "-object can-bus,id=bus1 -device ctucan_pci,canbus0=bus1,canbus1=bus1 -trace memory_region_ops_read -trace memory_region_ops_write -D $ctu/trace.log" \
		-- target/release/rcan-bench-ctu ${RCAN_BENCH_CTU_ARGS:---frames 2000 --rounds 3} |
		tee "$ctu/phases.txt" || crc=$?
	if grep -q '^CTU-PHASE' "$ctu/phases.txt" 2>/dev/null; then
		awk -v tag=CTU -v region=ctucan -f "$RCAN_ROOT/tools/testing/rcan/bench/sja-count.awk" \
			"$ctu/phases.txt" "$ctu/trace.log" | tee "$ctu/summary.txt"
		log "CTU CAN FD summary saved in $ctu/summary.txt"
		# The trace is large (tens of MB per thousand frames);
		# RCAN_BENCH_KEEP_TRACE=1 keeps it.
		[ "${RCAN_BENCH_KEEP_TRACE:-0}" = 1 ] || rm -f "$ctu/trace.log"
	else
		log "CTU CAN FD section produced no phases (see $ctu/console.log)"
	fi
	[ "$crc" = 0 ] || rc=$crc
fi
exit "$rc"

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
# can-bcm.ko. Never fails on a missed target.
# See Documentation/networking/rcan/benchmarks.rst.
#
#   bench.sh [rcan-bench options]     e.g. --stack mainline, --quick,
#                                     --part table, --part dsor, --part bcm
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
if [ "${RCAN_BENCH_SJA:-1}" != 0 ]; then
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
exit "$rc"

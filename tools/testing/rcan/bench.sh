#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# The benchmark command (make bench): boot ONE VM on the release test kernel
# and run rcan-bench in it, which measures mainline SocketCAN (can.ko,
# can-raw.ko, vcan echo=1) and our stack (rcan_pf, rcan_can, rcan_raw,
# rcan_loop), one after the other in alternating rounds, with the same
# CAN_RAW programs -- throughput, fan-out cost, latency -- and prints the
# figures, the ratios ours/mainline and a summary table; then (dsor part)
# our DSOR message protocol (rcan_dsor over rcan_loop) against mainline
# ISO-TP (can-isotp over vcan): goodput and CPU time per KiB. Never fails
# on a missed target. See Documentation/networking/rcan/benchmarks.rst.
#
#   bench.sh [rcan-bench options]     e.g. --stack mainline, --quick,
#                                     --part dsor (make bench BENCH_ARGS=...)
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
exit "$rc"

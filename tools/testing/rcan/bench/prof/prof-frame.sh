#!/bin/bash
# SPDX-License-Identifier: GPL-2.0
# Guest side: perf profile of CAN_RAW frames through the echoing device on
# the path hardware takes (canloop's echo through its receive FIFO and NAPI
# poll; mainline vcan echo=1 through netif_rx), each stack in turn
# (benchmarks.rst, "CAN_RAW per frame, profiled by instruction count").
# Run it in the VM under instruction counting, e.g.
#
#   RCAN_KVM=icount RCAN_KBUILD=$(. tools/testing/rcan/lib.sh; rcan_kbuild) \
#     bash tools/testing/rcan/vm-run.sh --timeout 3000 --out OUT -- \
#     bash tools/testing/rcan/bench/prof/prof-frame.sh mainline ours:BASE ours
#
# Each argument is a stack: "mainline" (RCAN_KBUILD's can, can-raw, vcan
# echo=1), "ours" (this tree's modules) or "ours:DIR" (the modules of
# another build, laid out as in the tree, like rcan-bench --ours-dir). For
# each, OUT gets the workload's phase marks without perf
# (marks-noperf-K.txt) and under perf (marks-K.txt), /proc/softirqs and
# /proc/stat before and after the timed rounds (cpus-{before,after}-K.txt),
# and the samples, leaf
# only, as perf script prints them with the modules still loaded
# (script-K.txt.gz); prof-frame-split.py turns them into the tables by
# category, prof-frame-syms.py by function.
# Env: N (frames per round, 20480), ROUNDS (3), BATCH (64), PERIOD
# (cpu-clock period in ns; under icount 1 ns = 1 instruction; 9973),
# CPU (the CPU the workload is pinned to, 0), PERF=0 (only the timed runs:
# to compare builds, e.g. ours:A ours:B ours:B ours:A).
set -u
cd "$(dirname "$0")/../../../../.." || exit 1
N=${N:-20480} ROUNDS=${ROUNDS:-3} BATCH=${BATCH:-64} PERIOD=${PERIOD:-9973} CPU=${CPU:-0}
out=${RCAN_OUT:-/tmp}
. tools/testing/rcan/bench/prof/stack.sh
i=0
for st in "$@"; do
	i=$((i + 1))
	stack_load "$st" || exit 1
	tag=$i-${st%%:*}
	wl="taskset -c $CPU python3 tools/testing/rcan/bench/prof/frame.py can0 $N"
	# one warm-up round, then the phases timed without perf (under icount:
	# instructions), then again under perf
	$wl 1 $BATCH > /dev/null || exit 1
	# Per-CPU softirq counts and CPU times around the timed rounds: what
	# the other CPU does without perf running (perf keeps it awake).
	cat /proc/softirqs /proc/stat > $out/cpus-before-$tag.txt
	$wl $ROUNDS $BATCH > $out/marks-noperf-$tag.txt || exit 1
	cat /proc/softirqs /proc/stat > $out/cpus-after-$tag.txt
	if [ "${PERF:-1}" = 0 ]; then
		echo "$tag: $(grep -c PHASE $out/marks-noperf-$tag.txt) phases"
		continue
	fi
	# Leaf samples only (no -g): the kernel's guess unwinder scans the
	# whole stack per sample, which would cost more than the period.
	JITTER=1 perf record -a -k CLOCK_MONOTONIC -e cpu-clock -c $PERIOD -o /tmp/perf.data -- \
		$wl $ROUNDS $BATCH > $out/marks-$tag.txt 2> $out/perf-$tag.log || exit 1
	perf script -i /tmp/perf.data --ns -F comm,tid,cpu,time,ip,sym,symoff,dso 2>> $out/perf-$tag.log |
		gzip -1 > $out/script-$tag.txt.gz
	rm -f /tmp/perf.data
	echo "$tag: $(grep -c PHASE $out/marks-$tag.txt) phases, $(zcat $out/script-$tag.txt.gz | wc -l) samples"
done
stack_unload
exit 0

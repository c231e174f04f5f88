#!/bin/bash
# SPDX-License-Identifier: GPL-2.0
# Guest side: perf profile of bind(2) and close(2) of N CAN_RAW sockets,
# each stack in turn (benchmarks.rst, "Instruction-count profile of bind
# and close"). Run it in the VM under instruction counting, e.g.
#
#   RCAN_KVM=icount RCAN_KBUILD=$(bash tools/testing/rcan/build-kernel.sh) \
#     bash tools/testing/rcan/vm-run.sh --timeout 3000 --out OUT -- \
#     bash tools/testing/rcan/bench/prof/prof-bindclose.sh mainline ours ours:DIR
#
# Each argument is a stack: "mainline" (RCAN_KBUILD's can, can-raw, vcan),
# "ours" (this tree's modules) or "ours:DIR" (the modules of another build,
# laid out as in the tree, like rcan-bench --ours-dir). For each, OUT gets
# the workload's phase marks (marks-K.txt) and the samples, leaf first, as
# perf script prints them with the modules still loaded (script-K.txt.gz);
# prof-split.py turns them into the table. Env: N (10000), ROUNDS (3),
# PERIOD (cpu-clock period in ns; under icount 1 ns = 1 instruction),
# PERF=0 (only the timed run: to compare builds, e.g. ours:A ours:B ours:B ours:A).
set -u
cd "$(dirname "$0")/../../../../.." || exit 1
N=${N:-10000} ROUNDS=${ROUNDS:-3} PERIOD=${PERIOD:-20000}
out=${RCAN_OUT:-/tmp}
. tools/testing/rcan/bench/prof/stack.sh
i=0
for st in "$@"; do
	i=$((i + 1))
	stack_load "$st" || exit 1
	tag=$i-${st%%:*}
	# one warm-up round, then the phases timed without perf (under icount:
	# instructions), then again under perf
	taskset -c 0 python3 tools/testing/rcan/bench/prof/bindclose.py can0 $N 1 > /dev/null || exit 1
	taskset -c 0 python3 tools/testing/rcan/bench/prof/bindclose.py can0 $N $ROUNDS \
		> $out/marks-noperf-$tag.txt || exit 1
	if [ "${PERF:-1}" = 0 ]; then
		echo "$tag: $(grep -c PHASE $out/marks-noperf-$tag.txt) phases"
		continue
	fi
	# Leaf samples only (no -g): the kernel's guess unwinder scans the
	# whole stack per sample, which would cost more than the period.
	JITTER=1 perf record -a -k CLOCK_MONOTONIC -e cpu-clock -c $PERIOD -o /tmp/perf.data -- \
		taskset -c 0 python3 tools/testing/rcan/bench/prof/bindclose.py can0 $N $ROUNDS \
		> $out/marks-$tag.txt 2> $out/perf-$tag.log || exit 1
	perf script -i /tmp/perf.data --ns -F comm,cpu,time,ip,sym,symoff,dso 2>> $out/perf-$tag.log |
		gzip -1 > $out/script-$tag.txt.gz
	rm -f /tmp/perf.data
	echo "$tag: $(grep -c PHASE $out/marks-$tag.txt) phases, $(zcat $out/script-$tag.txt.gz | wc -l) samples"
done
stack_unload
exit 0

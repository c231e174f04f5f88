#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# canzlogd's cost, the figures in Documentation/networking/rcan/canzlogd.rst:
# CPU time per second at a given frame rate, and bytes per frame on disk.
# Runs INSIDE the test VM (as root), on rcan's canloop:
#
#   . tools/testing/rcan/lib.sh
#   bash tools/testing/rcan/vm-run.sh --timeout 900 -- \
#       bash tools/testing/rcan/daemons-measure.sh [FRAMES] [GAP_MS] [FLUSH_MS]
#
# cangen sends FRAMES (default 10000) random classic frames (random id,
# length and data: the worst case for compression) every GAP_MS (default 1,
# so at most 1000 frames/s); canzlogd's user+system time comes from
# /proc/PID/stat. In a software-emulated VM every figure is several times
# what the same work costs on hardware: compare runs, not absolutes.
set -euo pipefail
cd "$(dirname "$0")/../../.."
n=${1:-10000}
gap=${2:-1}
flush=${3:-1000}
if ! grep -q '^rcan_loop ' /proc/modules; then
	insmod net/can/rcan_pf.ko
	insmod net/can/rcan_raw.ko
	insmod drivers/net/can/rcan_loop.ko
	ip link set can0 up
fi
dir=$(mktemp -d)
# RCAN_MEASURE_OPTS: more canzlogd options (e.g. "--no-fsync --level 6").
# Pinned: the sender (and the loopback device's echo, which runs in the
# NET_RX softirq of the sending CPU) on CPU 0, the loggers on CPU 1, so
# the loggers charge only their own system calls; in an overloaded
# emulated VM system time stays noisy all the same (canzlogd.rst,
# Measurements). With one CPU, no pinning.
pin0='' pin1=''
if [ "$(nproc)" -ge 2 ]; then pin0="taskset -c 0" pin1="taskset -c 1"; fi
# shellcheck disable=SC2086 # word splitting of the options is meant
$pin1 target/release/canzlogd -d "$dir" --flush-ms "$flush" ${RCAN_MEASURE_OPTS:-} can0 2>"$dir.err" &
pid=$!
# The baseline: can-utils' candump -l, uncompressed, on the same frames.
(cd "$dir" && exec $pin1 candump -l can0) &
cpid=$!
sleep 2
hz=$(getconf CLK_TCK)
# utime and stime separately: tick-based accounting charges softirq work
# (the CAN receive path of every socket) to whatever task it interrupts,
# so stime is noisy; utime is the program's own work.
ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
uticks() { awk '{print $14}' "/proc/$1/stat"; }
i0=$(ticks $pid)
sleep 5
i1=$(ticks $pid)
echo "canzlogd: idle: $((i1 - i0)) ticks of CPU in 5 s (CLK_TCK $hz); clocksource $(cat /sys/devices/system/clocksource/clocksource0/current_clocksource)"
t0=$(ticks $pid)
u0=$(uticks $pid)
c0=$(ticks $cpid)
cu0=$(uticks $cpid)
# RCAN_MEASURE_STRACE=1: also count canzlogd's system calls (slows it).
if [ "${RCAN_MEASURE_STRACE:-0}" = 1 ]; then
	strace -c -f -p "$pid" -o "$dir.strace" &
	spid=$!
	sleep 1
fi
s0=$(date +%s.%N)
$pin0 cangen can0 -g "$gap" -n "$n"
s1=$(date +%s.%N)
sleep 1.2 # one flush interval, so the last frames are compressed too
t1=$(ticks $pid)
u1=$(uticks $pid)
c1=$(ticks $cpid)
cu1=$(uticks $cpid)
if [ -n "${spid:-}" ]; then
	kill -INT "$spid"
	wait "$spid" || true
	cat "$dir.strace"
fi
kill -TERM "$pid" "$cpid"
wait "$pid"
wait "$cpid" || true
echo "candump -l: CPU $(awk -v a="$c0" -v b="$c1" -v hz="$hz" 'BEGIN { printf "%.2f", (b - a) / hz }') s (user $(awk -v a="$cu0" -v b="$cu1" -v hz="$hz" 'BEGIN { printf "%.2f", (b - a) / hz }') s) for the same frames, $(wc -c < "$dir"/candump-*.log) bytes uncompressed"
bytes=$(cat "$dir"/*.log.gz | wc -c)
lines=$(zcat "$dir"/*.log.gz | grep -c '^(')
raw=$(zcat "$dir"/*.log.gz | grep '^(' | wc -c)
zcat "$dir"/*.log.gz | grep '^#' | sed 's/^/canzlogd: note: /'
awk -v n="$n" -v lines="$lines" -v s0="$s0" -v s1="$s1" -v t0="$t0" -v t1="$t1" \
	-v u0="$u0" -v u1="$u1" -v hz="$hz" -v bytes="$bytes" -v raw="$raw" -v flush="$flush" 'BEGIN {
	el = s1 - s0; fps = n / el; cpu = (t1 - t0) / hz
	printf "canzlogd: %d frames sent in %.2f s (%.0f frames/s), %d logged, flush %d ms\n", n, el, fps, lines, flush
	printf "canzlogd: CPU %.2f s = %.2f %% of one CPU, %.2f %% per 1,000 frames/s\n", cpu, 100 * cpu / el, 100 * cpu / el / (fps / 1000)
	ucpu = (u1 - u0) / hz
	printf "canzlogd: user CPU %.2f s = %.2f %% of one CPU, %.2f %% per 1,000 frames/s\n", ucpu, 100 * ucpu / el, 100 * ucpu / el / (fps / 1000)
	printf "canzlogd: %d bytes on disk = %.2f bytes/frame (text %.1f bytes/frame, ratio %.2f)\n", bytes, bytes / lines, raw / lines, raw / bytes
}'

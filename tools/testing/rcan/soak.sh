#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# make soak: the VM stages of make check (release shards, mainline, debug
# shards and the fuzzer), RUNS times in a row (default 3) while
# `stress-ng --cpu LOAD` (default 2, as many workers as the machine has
# cores) keeps the host busy beside them, to show that no test depends on
# the host's speed (issue "a test suite that scales": zero flaky tests).
# Each run prints its own report (run-tests.sh); the last line counts the
# tests of all runs: "N passed, M failed". The host stages are left out
# (RCAN_SKIP_HOST=1): they do not run in a VM and have no timing to
# depend on. RCAN_JOBS and RCAN_SHARDS_* apply as in make check.
set -uo pipefail
. "$(dirname "$0")/lib.sh"
cd "$RCAN_ROOT"

runs=${RUNS:-3}
load=${LOAD:-2}
[[ $runs =~ ^[1-9][0-9]*$ ]] || die "RUNS wants a number >= 1"
[[ $load =~ ^[0-9]+$ ]] || die "LOAD wants a number of stress-ng CPU workers"
command -v stress-ng > /dev/null || die "stress-ng not found (tools/testing/rcan/setup.sh installs it)"

stress_pid=
if [ "$load" -gt 0 ]; then
	# Bounded: it ends by itself after a day even if this script is killed.
	stress-ng --cpu "$load" --timeout 86400 --quiet &
	stress_pid=$!
	trap 'kill "$stress_pid" 2> /dev/null' EXIT
fi
log "soak: $runs runs of the VM stages beside stress-ng --cpu $load"
passed=0
failed=0
for i in $(seq 1 "$runs"); do
	echo "=== soak run $i of $runs ($(date -u +%H:%M:%S) UTC, load $(cut -d' ' -f1-3 /proc/loadavg))"
	out=$(mktemp)
	RCAN_SKIP_HOST=1 bash "$RCAN_ROOT/tools/testing/rcan/run-tests.sh" 2>&1 | tee "$out"
	line=$(grep -E '^[0-9]+ passed, [0-9]+ failed' "$out" | tail -n 1)
	rm -f "$out"
	p=${line%% passed*}
	f=${line#*passed, }
	f=${f%% failed*}
	[ -n "$line" ] || { p=0; f=1; }
	echo "=== soak run $i: $p passed, $f failed"
	passed=$((passed + p))
	failed=$((failed + f))
done
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]

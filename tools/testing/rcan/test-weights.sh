#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Writes tests/vm/weights.txt, the recorded seconds of every VM test on
# the release and on the debug kernel, from the test lines ("ok - NAME #
# S s, cpu C s") of a whole make check: the logs it keeps in
# target/rcan-check/ (vm-release*.log, vm-debug*.log; mainline's are not
# used, its one VM needs no split). rcan-vmtest --shard balances its
# shards by these figures (tests/vm/src/shard.rs). A test missing from a
# kernel's logs (release-only tests on debug) gets "-". Run it after a
# whole make check when the suite's tests changed much; the split only
# needs the figures roughly right.
#
#   test-weights.sh [LOG_DIR]     (default target/rcan-check)
set -euo pipefail
. "$(dirname "$0")/lib.sh"
dir=${1:-$RCAN_ROOT/target/rcan-check}
out=$RCAN_ROOT/tests/vm/weights.txt
shopt -s nullglob
rel=("$dir"/vm-release*.log)
dbg=("$dir"/vm-debug*.log)
[ ${#rel[@]} -gt 0 ] && [ ${#dbg[@]} -gt 0 ] || die "no vm-release*.log and vm-debug*.log in $dir (run make check first)"
times() {
	sed -nE 's/^(not )?ok - ([A-Za-z0-9_]+).* # ([0-9.]+) s, cpu [0-9.]+ s$/\2 \3/p' "$@" | sort -u -k1,1
}
{
	echo "# name release-seconds debug-seconds: recorded by tools/testing/rcan/test-weights.sh"
	echo "# from a make check of $(date -u +%Y-%m-%d); rcan-vmtest --shard balances by them"
	join -a1 -a2 -e - -o 0,1.2,2.2 <(times "${rel[@]}") <(times "${dbg[@]}")
} > "$out.tmp"
mv "$out.tmp" "$out"
log "wrote $out ($(grep -vc '^#' "$out") tests)"

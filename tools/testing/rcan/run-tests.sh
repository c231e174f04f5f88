#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# The test command (make check, called by .ci/run): host tests (cargo test,
# then tests/frontdoor.sh: how the kernel build fails and shares its cache,
# then tests/unsafe.sh: the ceiling on unsafe outside rust/glue/, then
# tests/dkms.sh: dkms.conf names every module Kbuild builds),
# then the VM suite on the release kernel, its CAN_RAW/can-utils subset
# against mainline SocketCAN (can.ko, can-raw.ko, vcan.ko of the same
# kernel) in a VM boot of its own, and the suite again on the debug kernel
# (KASAN, lockdep, kmemleak), each VM run failing on any kernel report,
# followed in that boot by a bounded run of the syscall fuzzer (tests/fuzz,
# rcan-fuzz): a fixed seed and a time-derived one, printed, so that each
# CI run also tries a new sequence (counted as one test, stage
# fuzz-debug). Prints one closing "N passed, M failed" line over all
# stages.
#
# RCAN_SKIP_DEBUG=1 skips the debug-kernel stages (for quick local runs).
# RCAN_FUZZ_SECONDS (default 45) is the fuzzer's time per seed; a longer
# run is `make fuzz SECONDS=N`.
set -uo pipefail
. "$(dirname "$0")/lib.sh"
cd "$RCAN_ROOT"

passed=0
failed=0
log_dir=$(mktemp -d)

# Adds the "N passed, M failed" counts of a stage log; a stage that exited
# non-zero without a count line counts as one failure.
tally() {
	local name=$1 rc=$2 logf=$3 line p f
	line=$(grep -E '^[0-9]+ passed, [0-9]+ failed' "$logf" | tail -n 1)
	if [ -n "$line" ]; then
		p=${line%% passed*}
		f=${line#*passed, }
		f=${f%% failed*}
	else
		p=0
		f=0
	fi
	if [ "$rc" != 0 ] && [ "$f" = 0 ]; then
		f=1
		echo "rcan: stage '$name' failed (exit $rc)"
	fi
	echo "rcan: stage '$name': $p passed, $f failed"
	passed=$((passed + p))
	failed=$((failed + f))
}

echo "=== host: cargo test"
cargo test --workspace 2>&1 | tee "$log_dir/host.log"
rc=${PIPESTATUS[0]}
hp=$(grep -Eo 'test result: [a-z]+\. [0-9]+ passed' "$log_dir/host.log" | awk '{s+=$4} END {print s+0}')
hf=$(grep -Eo '[0-9]+ failed;' "$log_dir/host.log" | awk '{s+=$1} END {print s+0}')
echo "$hp passed, $hf failed" >> "$log_dir/host.log"
tally host "$rc" "$log_dir/host.log"

# The front door itself (seconds): a failed kernel build stops make with its
# own message, runs sharing a cache wait for each other. Uses caches and a
# small tarball of its own, never the real cache.
echo "=== host: front door (build-kernel.sh, make modules)"
bash "$RCAN_ROOT/tools/testing/rcan/tests/frontdoor.sh" 2>&1 | tee "$log_dir/frontdoor.log"
tally frontdoor "${PIPESTATUS[0]}" "$log_dir/frontdoor.log"

# The unsafe ratchet: `unsafe` in kernel-module Rust outside rust/glue/
# must not exceed the ceiling recorded in tools/testing/rcan/unsafe-ceiling.
echo "=== host: unsafe outside rust/glue (ratchet)"
bash "$RCAN_ROOT/tools/testing/rcan/tests/unsafe.sh" 2>&1 | tee "$log_dir/unsafe.log"
tally unsafe "${PIPESTATUS[0]}" "$log_dir/unsafe.log"

# dkms.conf names every module the Kbuild files build (seconds).
echo "=== host: dkms.conf against the Kbuild files"
bash "$RCAN_ROOT/tools/testing/rcan/tests/dkms.sh" 2>&1 | tee "$log_dir/dkms.log"
tally dkms "${PIPESTATUS[0]}" "$log_dir/dkms.log"

# The tree whose modules a stage loads. Release: the checkout itself
# (make check built them). Debug: a copy of the checkout's sources (its
# tracked and untracked, not ignored files) in target/rcan-debug/, kept
# between runs so that its build is incremental, with target/ linked back
# for the user-space programs. The checkout then keeps its release modules,
# and nothing is rebuilt after the debug stages (that rebuild took minutes
# of every make check). Outside a git checkout the debug modules are built
# in place, and the release ones rebuilt at the end, as before.
debug_root=$RCAN_ROOT
debug_in_place=1
make_debug_root() {
	local dst=$RCAN_ROOT/target/rcan-debug
	git -C "$RCAN_ROOT" rev-parse --git-dir > /dev/null 2>&1 || return 0
	mkdir -p "$dst" || return 1
	# The copy's file list is kept beside it: a file gone from the
	# checkout since the last copy is deleted from the copy too, so the
	# debug build never sees a source the release build no longer has.
	local files
	files=$(cd "$RCAN_ROOT" && git ls-files --cached --others --exclude-standard | sort -u) || return 1
	if [ -f "$dst/.rcan-files" ]; then
		comm -23 "$dst/.rcan-files" - <<< "$files" | while IFS= read -r f; do
			rm -f -- "$dst/$f"
		done
	fi
	(cd "$RCAN_ROOT" && tar --ignore-failed-read -T - -cf - <<< "$files") |
		tar -xf - -C "$dst" || return 1
	printf '%s\n' "$files" > "$dst/.rcan-files" || return 1
	[ -L "$dst/target" ] || ln -s .. "$dst/target" || return 1
	debug_root=$dst
	debug_in_place=0
}

vm_stage() {
	local variant=$1 root=$RCAN_ROOT limit=2400 rc out
	local cmd=(target/release/rcan-vmtest)
	echo "=== VM suite on the $variant kernel"
	if [ "$variant" = debug ]; then
		# The VM runs in the checkout, which it sees at its host path even
		# below /tmp (vm-run.sh binds it there); the programs load the
		# debug modules from target/rcan-debug (--root), whose target/ is
		# the checkout's.
		if ! make_debug_root; then
			echo "rcan: copying the sources to $RCAN_ROOT/target/rcan-debug failed"
			tally "vm-$variant" 1 /dev/null
			tally fuzz-debug 1 /dev/null
			return
		fi
		root=$debug_root
		cmd+=(--root "$root")
	fi
	if ! RCAN_KERNEL=$variant make --no-print-directory -C "$root" modules > "$log_dir/build-$variant.log" 2>&1; then
		tail -n 40 "$log_dir/build-$variant.log"
		tally "vm-$variant" 1 /dev/null
		[ "$variant" = debug ] && tally fuzz-debug 1 /dev/null
		return
	fi
	# The debug stage took 1,432 to 2,268 s in quiet fresh-clone runs
	# (build.rst); the release stage takes a quarter of its 40 min. On the
	# debug kernel the syscall fuzzer follows the suite in the same boot
	# (fuzz_cmd): one boot and one end-of-run kmemleak scan fewer, about
	# three minutes of every make check.
	if [ "$variant" = debug ]; then
		limit=$((3300 + 900))
		fuzz_cmd
		cmd=(bash -c "$(printf '%q ' "${cmd[@]}"); echo \$? > \"\$RCAN_OUT/suite.rc\"; echo '$fuzz_marker'; $(printf '%q ' "${fuzz[@]}"); echo \$? > \"\$RCAN_OUT/fuzz.rc\"")
	fi
	out=$log_dir/out-$variant
	mkdir -p "$out"
	# RCAN_KBUILD: install_autoload installs the kernel's own modules
	# beside ours and runs make install KDIR=... against it; other tests
	# load the same kernel's mainline CAN modules to compare in one boot.
	RCAN_KERNEL=$variant RCAN_KBUILD=$(RCAN_KERNEL=$variant bash "$RCAN_ROOT/tools/testing/rcan/build-kernel.sh") \
		bash "$RCAN_ROOT/tools/testing/rcan/vm-run.sh" --timeout "$limit" --out "$out" --qemu-extra "$RCAN_QEMU_CAN" -- \
		"${cmd[@]}" 2>&1 | tee "$log_dir/vm-$variant.log"
	rc=${PIPESTATUS[0]}
	if [ "$variant" != debug ]; then
		tally "vm-$variant" "$rc" "$log_dir/vm-$variant.log"
		return
	fi
	# One boot, two stages: each its own exit status (written by the guest)
	# and its own part of the log. A status the guest did not write is the
	# VM's (124 timeout, 125 crash): the stage that was running, and the
	# fuzzer if it never started. A kernel report (126) after both ended
	# counts against the suite; the report itself is printed above.
	local suite_rc fuzz_rc
	suite_rc=$(cat "$out/suite.rc" 2>/dev/null || echo "$rc")
	fuzz_rc=$(cat "$out/fuzz.rc" 2>/dev/null || echo "$rc")
	if [ "$rc" = 126 ] && [ "$suite_rc" = 0 ] && [ "$fuzz_rc" = 0 ]; then
		suite_rc=126
	fi
	sed -n "/^$fuzz_marker/q;p" "$log_dir/vm-debug.log" > "$log_dir/suite-debug.log"
	sed -n "/^$fuzz_marker/,\$p" "$log_dir/vm-debug.log" > "$log_dir/fuzz-debug.log"
	tally vm-debug "$suite_rc" "$log_dir/suite-debug.log"
	tally fuzz-debug "$fuzz_rc" "$log_dir/fuzz-debug.log"
}

# The portable tests against mainline: they must pass there, which shows
# that they encode mainline behaviour. Needs only the kernel (its mainline
# CAN modules) and rcan-vmtest, not our modules. The CAN_BCM tests
# (tests/vm/src/cases/bcm.rs) run here against can-bcm.ko and in the VM
# stages against rcan_bcm.
mainline_stage() {
	local kbuild
	echo "=== VM suite, CAN_RAW, can-utils and CAN_BCM tests, against mainline SocketCAN (release kernel)"
	if ! kbuild=$(RCAN_KERNEL=release bash "$RCAN_ROOT/tools/testing/rcan/build-kernel.sh" 2>"$log_dir/build-mainline.log"); then
		tail -n 40 "$log_dir/build-mainline.log"
		tally vm-mainline 1 /dev/null
		return
	fi
	RCAN_KERNEL=release RCAN_KBUILD=$kbuild RCAN_VMTEST_STACK=mainline \
		bash "$RCAN_ROOT/tools/testing/rcan/vm-run.sh" --timeout 2400 --qemu-extra "$RCAN_QEMU_CAN" -- \
		target/release/rcan-vmtest 2>&1 | tee "$log_dir/vm-mainline.log"
	tally vm-mainline "${PIPESTATUS[0]}" "$log_dir/vm-mainline.log"
}

# The syscall fuzzer on the debug kernel, after the suite in the debug
# stage's boot (vm_stage), with the debug modules. Seed 1 always; the
# second seed is the time, printed so that a failure can be replayed
# (Documentation/networking/rcan/robustness.rst). Sets fuzz (the command)
# and prints the seeds.
fuzz_marker='=== syscall fuzzer: the suite is done, fuzzing in the same boot'
fuzz_cmd() {
	local tseed
	tseed=${RCAN_FUZZ_SEED:-$(date +%s)}
	echo "=== syscall fuzzer on the debug kernel: seeds 1 and $tseed (time-derived), ${RCAN_FUZZ_SECONDS:-45} s each, after the suite in its boot"
	fuzz=(target/release/rcan-fuzz --root "$debug_root" --seed 1 --seed "$tseed"
		--seconds "${RCAN_FUZZ_SECONDS:-45}" --iterations 1000000)
}

vm_stage release
mainline_stage
if [ "${RCAN_SKIP_DEBUG:-0}" != 1 ]; then
	vm_stage debug
	# Leave release modules in the tree, as `make modules` would, if the
	# debug ones were built in place.
	if [ "$debug_in_place" = 1 ]; then
		RCAN_KERNEL=release make --no-print-directory modules > /dev/null 2>&1 || true
	fi
fi

rm -rf "$log_dir"
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]

#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Host tests of the front door (make modules, build-kernel.sh): a failed
# kernel build stops make with its own message last, and runs sharing a
# cache wait for each other. Run by make check (run-tests.sh, stage
# "frontdoor"); takes seconds: every run uses a cache of its own in a
# temporary directory (never ~/.cache/rcan) and a small tarball made here, a
# fake linux-source-6.12 whose Makefile "builds" in a second. Prints one
# "ok"/"not ok" line per test and a closing "N passed, M failed".
set -uo pipefail
# shellcheck source=lib.sh source-path=SCRIPTDIR/..
. "$(dirname "$0")/../lib.sh"

# Nothing of the caller's make (make check KDIR=..., its jobserver) or
# cache may reach the runs below.
unset MAKEFLAGS MFLAGS MAKELEVEL MAKEOVERRIDES KDIR RCAN_KBUILD
export RCAN_KERNEL=release
work=$(mktemp -d "${TMPDIR:-/tmp}/rcan-frontdoor.XXXXXX")
trap 'rm -rf "$work"' EXIT
bk="$RCAN_ROOT/tools/testing/rcan/build-kernel.sh"
real_tar=$(command -v tar)

. "$(dirname "$0")/check.sh"

# The fake kernel source: a Makefile with the targets build-kernel.sh runs
# (bzImage fails with $FAKE_KERNEL_ERROR when set; it waits up to 10 s for
# another run's "waiting" line in $FAKE_WAIT_FOR files, so that two runs
# surely overlap), merge_config.sh appending the fragments, and enough
# files for tar to have work.
fake="$work/fake/linux-source-6.12"
mkdir -p "$fake/scripts/kconfig" "$fake/drivers"
cat >"$fake/Makefile" <<'EOF'
# Fake kernel for tools/testing/rcan/tests/frontdoor.sh.
tinyconfig:
	: >$(O)/.config
olddefconfig:
	@true
bzImage modules:
	@[ -z "$(FAKE_WAIT_FOR)" ] || for i in $$(seq 600); do grep -qs 'waiting for' $(FAKE_WAIT_FOR) && break; sleep 0.1; done
	@if [ -n "$(FAKE_KERNEL_ERROR)" ]; then echo "drivers/fake.c:1:1: error: $(FAKE_KERNEL_ERROR)" >&2; exit 2; fi
	echo $@ >>$(O)/built
EOF
cat >"$fake/scripts/kconfig/merge_config.sh" <<'EOF'
#!/bin/sh
# Fake: merge_config.sh -m -O DIR BASE FRAGMENT... appends the fragments.
shift 3
base=$1
shift
cat "$@" >>"$base"
EOF
chmod +x "$fake/scripts/kconfig/merge_config.sh"
for i in $(seq 200); do echo "$i" >"$fake/drivers/f$i.c"; done
tarball="$work/linux-source-6.12.tar"
"$real_tar" -C "$work/fake" -cf "$tarball" linux-source-6.12
export KERNEL_TARBALL=$tarball
# The files a complete extraction has, as "./path" lines.
"$real_tar" -tf "$tarball" | grep -v '/$' | sed 's|^linux-source-6.12/|./|' | sort >"$work/expected"

# fresh NAME: a new empty cache (and PATH directory for fake tools) per test.
fresh() {
	export RCAN_CACHE="$work/$1/cache"
	bin="$work/$1/bin"
	mkdir -p "$RCAN_CACHE" "$bin"
	ksrc=$(rcan_ksrc)
}

# complete DIR: DIR holds exactly the tarball's files.
complete() {
	[ -d "$1" ] && (cd "$1" && find . -type f | sort) | cmp -s - "$work/expected"
}

# No make step may run once the kernel build failed.
no_later_step() {
	! grep -qE 'gen-bindings|M=' "$1"
}

# 1. A failing tar (full disk, a broken package) stops make modules with
# tar's message last; no later step runs and no source tree is left.
fresh tar-fails
cat >"$bin/tar" <<'EOF'
#!/bin/sh
echo "tar: linux-source-6.12/arch/arm64/tools: Cannot stat: No such file or directory" >&2
echo "tar: Exiting with failure status due to previous errors" >&2
exit 2
EOF
chmod +x "$bin/tar"
PATH="$bin:$PATH" make -C "$RCAN_ROOT" --no-print-directory modules >"$work/out" 2>&1
rc=$?
last=$(tail -n 1 "$work/out")
[ "$rc" != 0 ]
check "tar failure: make modules exits non-zero" $? "exit $rc"
[[ $last == *"extracting $tarball"*"failed (tar exit 2): tar: linux-source-6.12/arch/arm64/tools: Cannot stat"*Stop.* ]]
check "tar failure: tar's message is make's last line" $? "last line: $last"
no_later_step "$work/out"
check "tar failure: no bindings or Kbuild step ran" $? "$(cat "$work/out")"
[ ! -e "$ksrc" ] && [ -z "$(find "$RCAN_CACHE/src" -name '*.extracting.*')" ]
check "tar failure: no source tree and no temporary directory left" $?

# 2. A failing kernel build stops make modules with the compiler's message
# and the build log's path last.
fresh build-fails
FAKE_KERNEL_ERROR="simulated build failure" make -C "$RCAN_ROOT" --no-print-directory modules >"$work/out" 2>&1
rc=$?
last=$(tail -n 1 "$work/out")
blog="$(rcan_kbuild)/build.log"
[ "$rc" != 0 ] && [[ $last == *"release kernel build failed (exit 2): drivers/fake.c:1:1: error: simulated build failure; full log: $blog"*Stop.* ]]
check "kernel build failure: make modules stops with the error and the log's path last" $? "exit $rc, last line: $last"
grep -q 'error: simulated build failure' "$blog" 2>/dev/null && [ ! -e "$(rcan_kbuild)/.rcan-complete" ]
check "kernel build failure: the build log has the error, the build is not marked complete" $?
no_later_step "$work/out"
check "kernel build failure: no bindings or Kbuild step ran" $? "$(cat "$work/out")"

# 3. An empty KDIR never reaches a step.
make -C "$RCAN_ROOT" --no-print-directory modules KDIR= >"$work/out" 2>&1
rc=$?
[ "$rc" != 0 ] && tail -n 1 "$work/out" | grep -q 'KDIR is empty' && no_later_step "$work/out"
check "make modules KDIR= stops before any step" $? "$(cat "$work/out")"
bash "$RCAN_ROOT/rust/bindings/gen-bindings.sh" "" "$work/bindings.rs" 2>"$work/out"
rc=$?
[ "$rc" != 0 ] && grep -q 'usage' "$work/out" && [ ! -e "$work/bindings.rs" ]
check "gen-bindings.sh refuses an empty KDIR" $? "exit $rc: $(cat "$work/out")"

# 4. Two extractions at once: one extracts, the other waits and says so;
# both end with the one complete tree.
fresh two-extractions
cat >"$bin/tar" <<EOF
#!/bin/sh
echo call >>"$work/two-extractions/tar-calls"
# Hold on until the other run waits (or has called tar too).
for i in \$(seq 600); do
	grep -qs 'waiting for' "$work"/two-extractions/err.* && break
	[ "\$(wc -l <"$work/two-extractions/tar-calls")" -gt 1 ] && break
	sleep 0.1
done
exec "$real_tar" "\$@"
EOF
chmod +x "$bin/tar"
PATH="$bin:$PATH" bash "$bk" --source >"$work/two-extractions/out.1" 2>"$work/two-extractions/err.1" &
p1=$!
PATH="$bin:$PATH" bash "$bk" --source >"$work/two-extractions/out.2" 2>"$work/two-extractions/err.2" &
p2=$!
wait "$p1"
rc1=$?
wait "$p2"
rc2=$?
[ "$rc1" = 0 ] && [ "$rc2" = 0 ] &&
	[ "$(cat "$work/two-extractions/out.1")" = "$ksrc" ] && [ "$(cat "$work/two-extractions/out.2")" = "$ksrc" ]
check "two extractions at once: both succeed and print the source directory" $? \
	"exits $rc1/$rc2: $(cat "$work"/two-extractions/err.*)"
complete "$ksrc"
check "two extractions at once: one complete tree" $? "$(cd "$ksrc" 2>/dev/null && find . -type f | sort | diff "$work/expected" - | head)"
[ "$(wc -l <"$work/two-extractions/tar-calls")" = 1 ] &&
	grep -q "waiting for another run (pid [0-9]*) to finish extracting the kernel source into $ksrc" "$work"/two-extractions/err.*
check "two extractions at once: tar ran once, the other run said it waits" $? "$(cat "$work"/two-extractions/err.*)"
[ -z "$(find "$RCAN_CACHE/src" -name '*.extracting.*')" ]
check "two extractions at once: no temporary directory left" $?

# 5. An extraction killed half-way (SIGKILL to the whole run, as a crash or
# a killed terminal would) leaves no source tree, even though the half tree
# already had its Makefile; the next run removes the leftover and
# extracts a complete tree.
fresh killed
cat >"$bin/tar" <<EOF
#!/bin/sh
# Half an extraction: the top directory and its Makefile, then hang.
mkdir -p "\$2/linux-source-6.12" && echo half >"\$2/linux-source-6.12/Makefile"
touch "$work/killed/started"
exec sleep 60
EOF
chmod +x "$bin/tar"
exec 3>&2 2>/dev/null # no "Killed" job notice
PATH="$bin:$PATH" setsid bash "$bk" --source >/dev/null 2>"$work/killed/err" &
pgid=$!
for _ in $(seq 600); do
	[ -e "$work/killed/started" ] && break
	sleep 0.1
done
kill -KILL -- "-$pgid"
wait "$pgid"
exec 2>&3 3>&-
[ -e "$work/killed/started" ] && [ ! -e "$ksrc" ]
check "killed extraction: no source tree left" $? "$(cat "$work/killed/err")"
out=$(timeout 30 bash "$bk" --source 2>"$work/killed/err")
rc=$?
[ "$rc" = 0 ] && [ "$out" = "$ksrc" ] && complete "$ksrc" &&
	[ -z "$(find "$RCAN_CACHE/src" -name '*.extracting.*')" ]
check "killed extraction: the next run extracts a complete tree and removes the leftover" $? \
	"exit $rc: $(cat "$work/killed/err")"

# 6. Two kernel builds of one variant at once: one builds, the other waits
# and says so, then uses that build.
fresh two-builds
export FAKE_WAIT_FOR="$work/two-builds/err.1 $work/two-builds/err.2"
bash "$bk" >"$work/two-builds/out.1" 2>"$work/two-builds/err.1" &
p1=$!
bash "$bk" >"$work/two-builds/out.2" 2>"$work/two-builds/err.2" &
p2=$!
wait "$p1"
rc1=$?
wait "$p2"
rc2=$?
unset FAKE_WAIT_FOR
kbuild=$(rcan_kbuild)
[ "$rc1" = 0 ] && [ "$rc2" = 0 ] &&
	[ "$(cat "$work/two-builds/out.1")" = "$kbuild" ] && [ "$(cat "$work/two-builds/out.2")" = "$kbuild" ] &&
	[ -e "$kbuild/.rcan-complete" ]
check "two builds at once: both succeed and print the build directory" $? \
	"exits $rc1/$rc2: $(cat "$work"/two-builds/err.*)"
[ "$(sort "$kbuild/built" 2>/dev/null | tr '\n' ' ')" = "bzImage modules " ] &&
	grep -q "waiting for another run (pid [0-9]*) to finish building the release kernel in $kbuild" "$work"/two-builds/err.*
check "two builds at once: the kernel was built once, the other run said it waits" $? \
	"built: $(tr '\n' ' ' 2>/dev/null <"$kbuild/built") $(cat "$work"/two-builds/err.*)"

check_summary
[ "$failed" = 0 ]

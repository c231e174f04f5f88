#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Build the Rust-enabled 6.12 test kernel into the cache, keyed by kernel
# version, config fragments and toolchain. Prints the build directory.
# RCAN_KERNEL=release (default) or debug selects the variant.
#
#   build-kernel.sh [--source] [--error-on-stdout]
#
#   --source           only extract the kernel source (if not yet done) and
#                      print its directory
#   --error-on-stdout  print the closing error message on stdout instead of
#                      stderr (the Makefile: $(shell ...) keeps only stdout
#                      and drops the exit status)
#
# A failure exits non-zero and ends with one line "rcan: WHAT failed ...",
# naming the build log ($RCAN_CACHE/kernel/<variant>-<key>/build.log) when
# the kernel build itself failed.
#
# Runs sharing a cache wait for each other (flock): on
# $RCAN_CACHE/src/linux-source-6.12.lock around the extraction, on
# $RCAN_CACHE/kernel/<variant>-<key>.lock around that kernel's build (lock
# order: build lock, then source lock); a run that waits says so. The source
# is extracted into a temporary directory beside its final place and renamed
# into place once tar succeeded, so the source directory exists only
# complete; a build directory is complete once it has .rcan-complete. An
# interrupted run leaves at most a temporary directory, which the next
# extraction removes.
set -euo pipefail
# shellcheck source=lib.sh source-path=SCRIPTDIR
. "$(dirname "$0")/lib.sh"

source_only=0
err_fd=2
for arg in "$@"; do
	case $arg in
	--source) source_only=1 ;;
	--error-on-stdout) err_fd=1 ;;
	*)
		echo "usage: build-kernel.sh [--source] [--error-on-stdout]" >&2
		exit 2
		;;
	esac
done

# The last word of a run: every failure path ends here or in on_exit.
failed=0
fail() {
	echo "rcan: $*" >&"$err_fd"
	failed=1
	exit 1
}

# Whatever stops the script: remove a half extraction, and give a failure
# that did not go through fail() (set -e, a signal) a closing line too.
tmp_src=
signal=
on_exit() {
	local rc=$1 cmd=$2
	# A second signal (make's exit hangs up the terminal) must not cut
	# the cleanup short.
	trap '' INT TERM HUP
	[ -z "$tmp_src" ] || rm -rf "$tmp_src"
	[ "$rc" = 0 ] && return
	[ "$failed" = 0 ] || return
	if [ -n "$signal" ]; then
		# To the terminal: the make that reads our stdout is likely
		# interrupted too.
		echo "rcan: build-kernel.sh interrupted (SIG$signal)" >&2
	else
		echo "rcan: build-kernel.sh: '$cmd' failed (exit $rc)" >&"$err_fd"
	fi
}
trap 'on_exit $? "$BASH_COMMAND"' EXIT
trap 'signal=INT; exit 130' INT
trap 'signal=TERM; exit 143' TERM
trap 'signal=HUP; exit 129' HUP

# take_lock FILE WHAT: waits for an exclusive flock on FILE, saying what it
# waits for when another run holds it; sets lock_fd. The lock lasts until
# lock_fd is closed or the script exits. FILE holds the holder's pid, for
# the waiters' message.
lock_fd=
take_lock() {
	local file=$1 what=$2 holder= i
	exec {lock_fd}<>"$file"
	if ! flock -n "$lock_fd"; then
		# The holder writes its pid just after it took the lock: a waiter
		# that looks in between finds the file empty (a loaded host makes
		# that window long), so it gives the pid up to 3 s to appear.
		for i in $(seq 30); do
			holder=$(cat "$file" 2>/dev/null || true)
			[ -n "$holder" ] && break
			sleep 0.1
		done
		log "waiting for another run${holder:+ (pid $holder)} to finish $what (lock: $file)"
		flock "$lock_fd"
	fi
	echo "$$" >"$file"
}

ksrc=$(rcan_ksrc)

# Makes $ksrc a complete source tree. The tree appears by rename(2) only
# after tar succeeded, so its Makefile means it is complete.
extract_source() {
	local src_fd rc first
	[ -f "$ksrc/Makefile" ] && return
	mkdir -p "$RCAN_CACHE/src"
	take_lock "$ksrc.lock" "extracting the kernel source into $ksrc"
	src_fd=$lock_fd
	# The run we waited for may have done it.
	if [ ! -f "$ksrc/Makefile" ]; then
		[ -f "$KERNEL_TARBALL" ] ||
			fail "$KERNEL_TARBALL not found: install Debian's linux-source-6.12 (make setup)"
		# Holding the lock, nobody else is extracting: these are left over
		# from runs that were killed.
		rm -rf "$ksrc".extracting.* "$ksrc"
		log "extracting $KERNEL_TARBALL"
		tmp_src=$(mktemp -d "$ksrc.extracting.XXXXXX")
		rc=0
		tar -C "$tmp_src" -xf "$KERNEL_TARBALL" 2>"$tmp_src/tar.err" || rc=$?
		if [ "$rc" != 0 ]; then
			head -n 20 "$tmp_src/tar.err" >&2 || true
			first=$(head -n 1 "$tmp_src/tar.err" 2>/dev/null || true)
			fail "extracting $KERNEL_TARBALL into $RCAN_CACHE/src failed (tar exit $rc)${first:+: $first}"
		fi
		cat "$tmp_src/tar.err" >&2
		[ -f "$tmp_src/linux-source-6.12/Makefile" ] ||
			fail "$KERNEL_TARBALL holds no linux-source-6.12/Makefile"
		mv -T "$tmp_src/linux-source-6.12" "$ksrc"
		rm -rf "$tmp_src"
		tmp_src=
	fi
	exec {src_fd}>&-
}

if [ "$source_only" = 1 ]; then
	extract_source
	echo "$ksrc"
	exit 0
fi

kbuild=$(rcan_kbuild)
if [ -f "$kbuild/.rcan-complete" ]; then
	echo "$kbuild"
	exit 0
fi
mkdir -p "$RCAN_CACHE/kernel"
take_lock "$kbuild.lock" "building the $RCAN_KERNEL kernel in $kbuild"
# The run we waited for may have built it.
if [ -f "$kbuild/.rcan-complete" ]; then
	echo "$kbuild"
	exit 0
fi

extract_source

frags=$(rcan_config_frags)

blog=$kbuild/build.log
log "building $RCAN_KERNEL kernel in $kbuild (cold build: several minutes; log: $blog)"
rm -rf "$kbuild"
mkdir -p "$kbuild"
: >"$blog"

# step WHAT CMD...: runs CMD with its output appended to the build log; if
# it fails, shows the log's tail and fails with the first error line and
# the log's path.
step() {
	local what=$1 rc=0 first
	shift
	echo "+ $what: $*" >>"$blog"
	"$@" >>"$blog" 2>&1 || rc=$?
	[ "$rc" = 0 ] && return
	tail -n 40 "$blog" >&2 || true
	# The compiler's or linker's first error, else make's first "***".
	first=$(grep -m 1 -E '(^|[^A-Za-z_-])(error|fatal)(\[[A-Z0-9]+\])?:' "$blog" 2>/dev/null ||
		grep -m 1 -F '***' "$blog" 2>/dev/null || true)
	first=${first:0:300}
	fail "$what failed (exit $rc)${first:+: $first}; full log: $blog"
}
mk() { make -C "$ksrc" O="$kbuild" LLVM=1 "$@"; }
step "make tinyconfig" mk tinyconfig
# shellcheck disable=SC2086 # $frags is a list of paths without blanks
step "merging the config fragments" "$ksrc/scripts/kconfig/merge_config.sh" -m -O "$kbuild" "$kbuild/.config" $frags
step "make olddefconfig" mk olddefconfig
# Every requested option must have survived olddefconfig.
bad=
for f in $frags; do
	while IFS= read -r line; do
		case "$line" in
		CONFIG_*=*)
			opt=${line%%=*}; val=${line#*=}
			[ "$val" = n ] && continue
			grep -qx "$line" "$kbuild/.config" && continue
			got=$(grep "^$opt=" "$kbuild/.config" || echo unset)
			log "config: wanted $line, got $got"
			bad=${bad:-"wanted $line, got $got"}
			;;
		esac
	done < "$f"
done
[ -z "$bad" ] || fail "config fragment not satisfied: $bad (all misses above); config: $kbuild/.config"
step "$RCAN_KERNEL kernel build" mk -j"$(nproc)" bzImage modules
touch "$kbuild/.rcan-complete"
echo "$kbuild"

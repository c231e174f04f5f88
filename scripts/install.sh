#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
#
# make install / make uninstall (see Documentation/networking/rcan/install.rst).
#
#   install.sh install   KDIR=... [DESTDIR=...] [PREFIX=/usr/local]
#   install.sh uninstall [DESTDIR=...] [PREFIX=/usr/local]
#
# install copies what `make` built, and builds nothing (so that `sudo make
# install` after a `make` as yourself leaves no root-owned files in the
# tree):
#   - the modules, with the kernel's own `modules_install` (M=, so into
#     /lib/modules/KVER/updates/, which depmod prefers to the kernel's own
#     directory), then depmod;
#   - the tools (those tools/mangen writes a man page for) into PREFIX/bin,
#     their man pages into PREFIX/share/man/man1, their bash, zsh and fish
#     completions into PREFIX/share/{bash-completion/completions,
#     zsh/site-functions,fish/vendor_completions.d};
#   - tools/install/rcan.conf into /etc/modprobe.d/.
# Every file it writes and every directory it creates is listed in the
# manifest PREFIX/share/rcan/install-manifest (paths without DESTDIR;
# another install adds to it). uninstall removes exactly those files, then
# those directories if they are empty, then runs depmod again for every
# kernel it had installed modules for.
set -euo pipefail

die() { echo "rcan install: $*" >&2; exit 1; }

action=${1:-}
DESTDIR=${DESTDIR:-}
PREFIX=${PREFIX:-/usr/local}
root=$(cd "$(dirname "$0")/.." && pwd)
manifest=$PREFIX/share/rcan/install-manifest
DEPMOD=${DEPMOD:-depmod}

# Files and created directories of this run, in install order.
new_files=()
new_dirs=()

# The parent of an absolute path without a trailing slash, in REPLY (no
# dirname process: under TCG on the debug kernel each process start costs
# about a second, and install made some 170 of them for paths alone).
parent() {
	REPLY=${1%/*}
	REPLY=${REPLY:-/}
}

# mkdir -p DIR (a path without DESTDIR), remembering every level it creates.
mkdir_rec() {
	local d=$1 missing=()
	while [ -n "$d" ] && [ "$d" != / ] && [ ! -d "$DESTDIR$d" ]; do
		missing=("$d" "${missing[@]}")
		parent "$d"
		d=$REPLY
	done
	[ ${#missing[@]} = 0 ] && return 0
	# One mkdir, parents first (it creates its arguments in order).
	mkdir -m 0755 "${missing[@]/#/"$DESTDIR"}"
	new_dirs+=("${missing[@]}")
}

# put MODE SRC DST (DST without DESTDIR)
put() {
	parent "$3"
	mkdir_rec "$REPLY"
	install -m "$1" "$2" "$DESTDIR$3"
	new_files+=("$3")
}

# put_into MODE DIR SRC... (DIR without DESTDIR): each SRC keeps its name.
put_into() {
	local mode=$1 dir=$2 src
	shift 2
	mkdir_rec "$dir"
	install -m "$mode" -t "$DESTDIR$dir" "$@"
	for src; do
		new_files+=("$dir/${src##*/}")
	done
}

depmod_for() {
	local kver=$1
	[ -d "$DESTDIR/lib/modules/$kver" ] || return 0
	"$DEPMOD" -a ${DESTDIR:+-b "$DESTDIR"} "$kver"
}

do_install() {
	local kdir=${KDIR:-}
	[ -n "$kdir" ] || die "KDIR is empty: give the kernel build directory the modules were built against (make install KDIR=...)"
	[ -f "$kdir/include/config/kernel.release" ] ||
		die "$kdir/include/config/kernel.release missing: KDIR must be a configured kernel build directory"
	local kver
	kver=$(cat "$kdir/include/config/kernel.release")

	# DESTDIR is the packager's staging root, not ours to record.
	[ -z "$DESTDIR" ] || mkdir -p "$DESTDIR"

	# Everything must be built already.
	[ -s "$root/modules.order" ] || die "no modules built in $root: run 'make' first (make install builds nothing)"
	local mods=() o ko
	while read -r o; do
		ko=${o#"$root"/}
		ko=${ko%.o}.ko
		[ -f "$root/$ko" ] || die "$ko missing: run 'make' first"
		mods+=("$ko")
	done < "$root/modules.order"
	[ -d "$root/target/man/man1" ] || die "no man pages in target/man: run 'make' first"
	local tools=() page t
	for page in "$root"/target/man/man1/*.1; do
		t=${page##*/}
		t=${t%.1}
		[ -x "$root/target/release/$t" ] || die "target/release/$t missing: run 'make' first"
		tools+=("$t")
	done

	# Modules: the kernel's modules_install (it copies modules.order's .ko
	# files to /lib/modules/KVER/updates/<their path>).
	mkdir_rec "/lib/modules/$kver"
	local d
	for ko in "${mods[@]}"; do
		parent "/lib/modules/$kver/updates/$ko"
		d=$REPLY
		while [ "$d" != "/lib/modules/$kver" ] && [ ! -d "$DESTDIR$d" ]; do
			new_dirs+=("$d")
			parent "$d"
			d=$REPLY
		done
	done
	make -s -C "$kdir" M="$root" LLVM=1 INSTALL_MOD_PATH="$DESTDIR" INSTALL_MOD_DIR=updates \
		DEPMOD=true modules_install
	for ko in "${mods[@]}"; do
		local dst=/lib/modules/$kver/updates/$ko
		[ -f "$DESTDIR$dst" ] || die "modules_install did not write $DESTDIR$dst"
		new_files+=("$dst")
	done
	depmod_for "$kver"

	local bindir=$PREFIX/bin mandir=$PREFIX/share/man share=$PREFIX/share
	# One install per directory whose files keep their names.
	local bins=() pages=() zsh=() fish=()
	for t in "${tools[@]}"; do
		bins+=("$root/target/release/$t")
		pages+=("$root/target/man/man1/$t.1")
		zsh+=("$root/target/man/completions/zsh/_$t")
		fish+=("$root/target/man/completions/fish/$t.fish")
	done
	put_into 0755 "$bindir" "${bins[@]}"
	put_into 0644 "$mandir/man1" "${pages[@]}"
	put_into 0644 "$share/zsh/site-functions" "${zsh[@]}"
	put_into 0644 "$share/fish/vendor_completions.d" "${fish[@]}"
	# bash-completion wants the command's own name, without .bash.
	for t in "${tools[@]}"; do
		put 0644 "$root/target/man/completions/bash/$t.bash" "$share/bash-completion/completions/$t"
	done
	put 0644 "$root/tools/install/rcan.conf" /etc/modprobe.d/rcan.conf

	# The manifest: "f PATH" per file, "d PATH" per created directory,
	# "k KVER" per kernel; merged with an earlier install's.
	parent "$manifest"
	mkdir_rec "$REPLY"
	local tmp
	tmp=$(mktemp)
	{
		[ ! -f "$DESTDIR$manifest" ] || cat "$DESTDIR$manifest"
		echo "k $kver"
		printf 'f %s\n' "${new_files[@]}" "$manifest"
		[ ${#new_dirs[@]} = 0 ] || printf 'd %s\n' "${new_dirs[@]}"
	} | sort -u > "$tmp"
	install -m 0644 "$tmp" "$DESTDIR$manifest"
	rm -f "$tmp"
	echo "rcan: installed ${#mods[@]} modules for $kver, ${#tools[@]} tools, rcan.conf; manifest $DESTDIR$manifest"
}

do_uninstall() {
	[ -f "$DESTDIR$manifest" ] || die "no manifest $DESTDIR$manifest: nothing installed there (same PREFIX and DESTDIR as make install?)"
	local kind p kvers=() dirs=() files=()
	while read -r kind p; do
		case $kind in
		f) files+=("$DESTDIR$p") ;;
		d) dirs+=("$p") ;;
		k) kvers+=("$p") ;;
		esac
	done < "$DESTDIR$manifest"
	[ ${#files[@]} = 0 ] || rm -f -- "${files[@]}"
	local kver
	for kver in "${kvers[@]}"; do
		# A /lib/modules/KVER that install created holds only depmod's
		# output besides our modules: remove that too, else depmod again.
		if printf '%s\n' "${dirs[@]}" | grep -qx "/lib/modules/$kver"; then
			rm -f "$DESTDIR/lib/modules/$kver"/modules.*
		else
			depmod_for "$kver"
		fi
	done
	# Deepest first, and only if empty (something else may live there now).
	# One rmdir: it goes through its arguments in order, skipping (with an
	# error we drop) those not empty or already gone.
	local deepest=()
	[ ${#dirs[@]} = 0 ] ||
		mapfile -t deepest <<<"$(printf '%s\n' "${dirs[@]}" | awk '{ print length($0) "\t" $0 }' | sort -rn | cut -f2-)"
	[ ${#dirs[@]} = 0 ] || rmdir -- "${deepest[@]/#/"$DESTDIR"}" 2>/dev/null || true
	echo "rcan: uninstalled what $DESTDIR$manifest listed"
}

case $action in
install) do_install ;;
uninstall) do_uninstall ;;
*) die "usage: install.sh install|uninstall (KDIR, DESTDIR, PREFIX from the environment)" ;;
esac

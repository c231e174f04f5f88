#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Build the Rust-enabled 6.12 test kernel into the cache, keyed by kernel
# version, config fragments and toolchain. Prints the build directory.
# RCAN_KERNEL=release (default) or debug selects the variant.
set -euo pipefail
. "$(dirname "$0")/lib.sh"

ksrc=$(rcan_ksrc)
kbuild=$(rcan_kbuild)
if [ -f "$kbuild/.rcan-complete" ]; then
	echo "$kbuild"
	exit 0
fi

if [ ! -f "$ksrc/Makefile" ]; then
	log "extracting $KERNEL_TARBALL"
	mkdir -p "$RCAN_CACHE/src"
	rm -rf "$ksrc.tmp" && mkdir -p "$ksrc.tmp"
	tar -C "$ksrc.tmp" -xf "$KERNEL_TARBALL"
	mv "$ksrc.tmp/linux-source-6.12" "$ksrc"
	rmdir "$ksrc.tmp"
fi

frags="$RCAN_ROOT/tools/testing/rcan/config/base.config"
[ "$RCAN_KERNEL" = debug ] && frags="$frags $RCAN_ROOT/tools/testing/rcan/config/debug.config"

log "building $RCAN_KERNEL kernel in $kbuild (cold build: several minutes)"
rm -rf "$kbuild"
mkdir -p "$kbuild"
mk() { make -C "$ksrc" O="$kbuild" LLVM=1 "$@"; }
mk tinyconfig >/dev/null
"$ksrc/scripts/kconfig/merge_config.sh" -m -O "$kbuild" "$kbuild/.config" $frags >/dev/null
mk olddefconfig >/dev/null
# Every requested option must have survived olddefconfig.
bad=0
for f in $frags; do
	while IFS= read -r line; do
		case "$line" in
		CONFIG_*=*)
			opt=${line%%=*}; val=${line#*=}
			[ "$val" = n ] && continue
			grep -qx "$line" "$kbuild/.config" ||
				{ log "config: wanted $line, got $(grep "^$opt=" "$kbuild/.config" || echo unset)"; bad=1; }
			;;
		esac
	done < "$f"
done
[ $bad = 0 ] || die "config fragment not satisfied"
mk -j"$(nproc)" bzImage modules >"$kbuild/build.log" 2>&1 ||
	{ tail -n 40 "$kbuild/build.log" >&2; die "kernel build failed"; }
touch "$kbuild/.rcan-complete"
echo "$kbuild"

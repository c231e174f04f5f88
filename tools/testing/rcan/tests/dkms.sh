#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# dkms.conf against the Kbuild files, run by make check (run-tests.sh,
# stage "dkms"): DKMS installs only the modules dkms.conf names, so a
# module added to a Kbuild file and forgotten there would silently be
# missing after the next kernel upgrade. Checks that dkms.conf names every
# module the Kbuild files build, at the directory Kbuild builds it in, and
# nothing else; that each goes to /updates; that MAKE builds against DKMS's
# kernel (KDIR=$kernel_source_dir). First checks the checker on a dkms.conf
# with one module left out, so a checker that finds nothing cannot pass.
# Then builds, installs and removes the tree with DKMS for real
# (dkms_round, below).
# Prints "ok"/"not ok" lines and a closing "N passed, M failed".
set -uo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
root=$(cd "$here/../../.." && pwd)
. "$(dirname "$0")/check.sh"

# The modules the Kbuild files build, "DIR/NAME" (DIR relative to the
# tree, no trailing slash), sorted: from ./Kbuild down every "obj-... +=
# dir/" line, collecting "obj-... += name.o" of each directory.
kbuild_modules() {
	local top=$1 dir=${2:-.} f line t
	f="$top/$dir/Kbuild"
	[ -f "$f" ] || return 0
	while read -r line; do
		for t in ${line#*+=}; do
			case $t in
			*/) kbuild_modules "$top" "$(echo "$dir/${t%/}" | sed 's|^\./||')" ;;
			*.o) echo "$dir/${t%.o}" | sed 's|^\./||' ;;
			esac
		done
	done < <(grep -E '^obj-(m|\$\(CONFIG_[A-Z0-9_]+\)) *\+=' "$f")
}

# What a dkms.conf declares, as DKMS reads it (it sources the file with
# kernel_source_dir set): "DIR/NAME DEST" per module, sorted, then
# "MAKE <MAKE[0]>".
dkms_modules() {
	(
		kernel_source_dir=/KSRC
		# shellcheck disable=SC1090
		. "$1"
		for i in "${!BUILT_MODULE_NAME[@]}"; do
			loc=${BUILT_MODULE_LOCATION[$i]%/}
			echo "${loc:-.}/${BUILT_MODULE_NAME[$i]} ${DEST_MODULE_LOCATION[$i]:-}"
		done | sort
		echo "MAKE ${MAKE[0]}"
	)
}

# check_conf CONF: empty output if CONF matches the Kbuild tree, else why.
check_conf() {
	local conf=$1 want got
	want=$(kbuild_modules "$root" | sort)
	[ -n "$want" ] || { echo "no module found in the Kbuild files"; return; }
	got=$(dkms_modules "$conf")
	diff <(echo "$want") <(echo "$got" | grep -v '^MAKE ' | cut -d' ' -f1) |
		grep '^[<>]' | sed -e 's/^</built by Kbuild, not in dkms.conf:/' -e 's/^>/in dkms.conf, not built by Kbuild:/'
	echo "$got" | grep -v '^MAKE ' | awk '$2 != "/updates" { print "not installed to /updates: " $0 }'
	echo "$got" | grep '^MAKE ' | grep -q 'KDIR=/KSRC\b' ||
		echo "MAKE does not build against \$kernel_source_dir: $(echo "$got" | grep '^MAKE ')"
	local pkg
	# shellcheck disable=SC1090,SC2034
	pkg=$(kernel_source_dir=/KSRC; . "$conf"; echo "${PACKAGE_NAME:-}")
	[ "$pkg" = rcan ] || echo "PACKAGE_NAME is '$pkg', not rcan"
}

# The checker on a dkms.conf that lacks the last module.
work=$(mktemp -d "${TMPDIR:-/tmp}/rcan-dkms.XXXXXX")
trap 'rm -rf "$work"' EXIT
last=$(grep -Eo 'BUILT_MODULE_NAME\[[0-9]+\]' "$root/dkms.conf" | tail -n 1 | grep -Eo '[0-9]+')
grep -Ev "^[A-Z_]+\[$last\]=" "$root/dkms.conf" > "$work/dkms.conf"
out=$(check_conf "$work/dkms.conf")
case $out in
*"built by Kbuild, not in dkms.conf:"*) check "checker: finds a module missing from dkms.conf" 0 ;;
*) check "checker: finds a module missing from dkms.conf" 1 "$out" ;;
esac

out=$(check_conf "$root/dkms.conf")
check "dkms.conf names every module the Kbuild files build ($(kbuild_modules "$root" | wc -l)), to /updates, built with KDIR=\$kernel_source_dir" \
	"$([ -z "$out" ]; echo $?)" "$out"

# A real DKMS round: dkms add, build, install and remove of the tree's
# sources (tracked and untracked, not ignored files, as a release tarball
# would hold them) against the release test kernel's build tree, as
# install.rst tells users to do, with DKMS's trees in the work directory
# (--dkmstree, --sourcetree, --installtree) so that nothing outside it is
# touched. DKMS's own depmod is skipped (it would run on the host's
# /lib/modules); depmod -b on the install tree checks instead that the
# installed modules' symbols resolve among themselves. The build is a whole
# module build from scratch: some 100 s of CPU on 2 cores.
dkms_round() {
	local kbuild kver ver src tree inst d want got log=$work/dkms.log
	kbuild=$(RCAN_KERNEL=release bash "$here/build-kernel.sh" 2>>"$log") ||
		{ echo "no release test kernel (build-kernel.sh failed)"; return; }
	kver=$(make -s -C "$kbuild" kernelrelease 2>>"$log")
	# shellcheck disable=SC1090,SC2034
	ver=$(kernel_source_dir=/KSRC; . "$root/dkms.conf"; echo "$PACKAGE_VERSION")
	src=$work/src tree=$work/tree inst=$work/root/lib/modules
	mkdir -p "$src/rcan-$ver" "$tree" "$inst/$kver"
	(cd "$root" && git ls-files --cached --others --exclude-standard 2>/dev/null |
		tar --ignore-failed-read -T - -cf - | tar -xf - -C "$src/rcan-$ver") ||
		{ echo "copying the sources failed"; return; }
	d=(dkms --dkmstree "$tree" --sourcetree "$src" --installtree "$inst")
	"${d[@]}" add -m rcan -v "$ver" >>"$log" 2>&1 || { echo "dkms add failed"; tail -n 20 "$log"; return; }
	"${d[@]}" build -m rcan -v "$ver" -k "$kver" --kernelsourcedir "$kbuild" >>"$log" 2>&1 ||
		{ echo "dkms build failed"; tail -n 30 "$log"; cat "$tree"/rcan/"$ver"/build/make.log 2>/dev/null | tail -n 30; return; }
	"${d[@]}" install --no-depmod -m rcan -v "$ver" -k "$kver" --kernelsourcedir "$kbuild" >>"$log" 2>&1 ||
		{ echo "dkms install failed"; tail -n 20 "$log"; return; }
	want=$(dkms_modules "$root/dkms.conf" | grep -v '^MAKE ' | cut -d' ' -f1 | sed 's|.*/||' | sort)
	got=$(cd "$inst/$kver/updates/dkms" 2>/dev/null && ls -- *.ko* 2>/dev/null | sed 's/\.ko.*//' | sort)
	[ "$want" = "$got" ] ||
		{ echo "installed modules differ from dkms.conf's:"; diff <(echo "$want") <(echo "$got"); return; }
	depmod -b "$work/root" "$kver" >>"$log" 2>&1 || { echo "depmod -b on the install tree failed"; return; }
	grep -q '^updates/dkms/rcan_raw.ko: updates/dkms/rcan_pf.ko$' "$inst/$kver/modules.dep" ||
		{ echo "modules.dep: rcan_raw does not depend on rcan_pf"; grep rcan_raw "$inst/$kver/modules.dep"; return; }
	# The vermagic of a module the test kernel built itself.
	local magic ours
	magic=$(modinfo -F vermagic "$kbuild/net/can/can.ko" 2>>"$log")
	ours=$(modinfo -F vermagic "$inst/$kver/updates/dkms/rcan_pf.ko" 2>>"$log")
	[ -n "$magic" ] && [ "$magic" = "$ours" ] ||
		{ echo "vermagic '$ours', the kernel's modules have '$magic'"; return; }
	"${d[@]}" remove --no-depmod -m rcan -v "$ver" --all >>"$log" 2>&1 ||
		{ echo "dkms remove failed"; tail -n 20 "$log"; return; }
	got=$(find "$inst/$kver" -name '*.ko*' | wc -l)
	[ "$got" = 0 ] || { echo "$got modules left installed after dkms remove"; return; }
	[ -z "$("${d[@]}" status 2>>"$log")" ] || { echo "dkms status not empty after remove: $("${d[@]}" status)"; return; }
	echo "ok $(echo "$want" | wc -l) $kver"
}
if command -v dkms >/dev/null && command -v git >/dev/null; then
	out=$(dkms_round)
	case $out in
	"ok "*)
		set -- $out
		check "dkms add, build, install (the $2 modules of dkms.conf, their dependencies resolved by depmod, the kernel's vermagic) and remove, against the release test kernel $3" 0
		;;
	*) check "dkms add, build, install and remove against the release test kernel" 1 "$out" ;;
	esac
else
	check "dkms add, build, install and remove: dkms (tools/testing/rcan/setup.sh installs it) or git not found" 1
fi
check_summary
[ "$failed" = 0 ]

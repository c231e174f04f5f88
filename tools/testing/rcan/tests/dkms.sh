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
check_summary
[ "$failed" = 0 ]

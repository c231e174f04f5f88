#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Counts `unsafe` in the kernel-module Rust outside the glue: every line
# of a .rs file under net/ and drivers/ of ROOT (default: this tree) that
# has the word `unsafe` (blocks, fns, impls, traits, extern blocks), not
# counting comment lines (//, //!, ///) and lint attributes such as
# #![forbid(unsafe_code)]. rust/glue/ is not under net/ or drivers/, so
# it is never counted; neither are build outputs (target/).
#
# Prints one line per file that has any, "COUNT PATH", then "total N".
# Used by tests/unsafe.sh (make check, stage "unsafe"), which holds the
# total to the ceiling recorded in unsafe-ceiling.
set -uo pipefail
root=${1:-$(cd "$(dirname "$0")/../../.." && pwd)}
cd "$root" || exit 2
total=0
while IFS= read -r f; do
	n=$(grep -Ew 'unsafe' "$f" |
		grep -Ev '^[[:space:]]*//' |
		grep -Evc '^[[:space:]]*#!?\[(forbid|deny|warn|allow)\(unsafe_code\)\][[:space:]]*$')
	if [ "$n" -gt 0 ]; then
		echo "$n $f"
		total=$((total + n))
	fi
done < <(find net drivers -name '*.rs' -not -path '*/target/*' 2>/dev/null | LC_ALL=C sort)
echo "total $total"

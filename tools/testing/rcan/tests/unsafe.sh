#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# The unsafe ratchet, run by make check (run-tests.sh, stage "unsafe"):
# the number of `unsafe` lines in kernel-module Rust outside rust/glue/
# (unsafe-count.sh) must not exceed the ceiling in unsafe-ceiling. On
# failure it prints the count of every file. First it checks the counter
# itself on a small tree of its own, so a counter that finds nothing
# cannot pass the ratchet. Prints "ok"/"not ok" lines and a closing
# "N passed, M failed".
set -uo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
root=$(cd "$here/../../.." && pwd)
count="$here/unsafe-count.sh"

# Every file's count on failure, however many.
CHECK_DETAIL_LINES=100000
. "$(dirname "$0")/check.sh"

# The counter on a known tree: a block, an impl and an fn count (3 lines);
# comments, a forbid attribute, glue and words that merely contain
# "unsafe" do not.
work=$(mktemp -d "${TMPDIR:-/tmp}/rcan-unsafe.XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/net/can" "$work/drivers/net/can" "$work/rust/glue"
cat > "$work/drivers/net/can/a.rs" <<'RS'
//! Has no `unsafe` in its docs that counts.
#![forbid(unsafe_code)]
// SAFETY: a comment that says unsafe
fn f() { let _ = unsafe { g() }; }
unsafe impl Send for X {}
RS
cat > "$work/net/can/b.rs" <<'RS'
/// unsafe in a doc comment
pub(crate) unsafe fn h() {}
fn not_counted_unsafely() {}
RS
echo 'fn glue() { unsafe { x() } }' > "$work/rust/glue/c.rs"
got=$(bash "$count" "$work")
want=$'2 drivers/net/can/a.rs\n1 net/can/b.rs\ntotal 3'
[ "$got" = "$want" ]
check "unsafe-count.sh counts blocks, fns and impls, not comments or glue" $? "$got"

ceiling=$(grep -Ev '^[[:space:]]*(#|$)' "$here/unsafe-ceiling" | head -n 1)
out=$(bash "$count" "$root")
total=$(printf '%s\n' "$out" | sed -n 's/^total //p')
if [[ "$ceiling" =~ ^[0-9]+$ ]] && [ -n "$total" ] && [ "$total" -le "$ceiling" ]; then
	check "unsafe outside rust/glue: $total, ceiling $ceiling" 0
else
	check "unsafe outside rust/glue: ${total:-?}, ceiling ${ceiling:-?} (unsafe-ceiling)" 1 \
		"$out"
fi

check_summary
[ "$failed" = 0 ]

#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# The misuse stage of make check (run-tests.sh, stage "misuse"): the
# soundness of the glue's safe API as a test. Each file in misuse/ is a
# module of safe code (#![forbid(unsafe_code)], as every protocol and
# driver file) that uses rust/glue/ the way a protocol or driver could;
# it is type-checked (rustc --emit=metadata, borrow checking included)
# in a crate of its own beside the glue and rcan_core, exactly as an
# out-of-tree module's crate root includes them, with the flags Kbuild
# gives out-of-tree Rust modules of the release kernel. A case passes
# only if it fails to compile with the error it names on its
# "// expect: EXXXX message" line, every error being that one and in the
# case's own file: a case refused for any other reason (a typo, a glue
# change that moved a name) fails the stage. Files named ok_*.rs are
# controls ("// expect: ok") that must compile, so a harness that refuses
# everything cannot pass. Each case opens with the finding of issue 39 it
# encodes. Takes seconds: no code generation, no link.
#
# Besides the cases, one source check: no safe function in rust/glue/
# (subfolders included) takes a raw pointer (issue 39; rawptr-fns.sh,
# which says what a text-level check sees and what it does not). The
# checker is first run on a small tree of its own with planted
# violations, so a checker that finds nothing cannot pass.
#
# Prints "ok"/"not ok" lines and a closing "N passed, M failed".
set -uo pipefail
# shellcheck source=lib.sh source-path=SCRIPTDIR/..
. "$(dirname "$0")/../lib.sh"
. "$(dirname "$0")/check.sh"

# Nothing of the caller's make (make check's jobserver) may reach the
# kernel's make below.
unset MAKEFLAGS MFLAGS MAKELEVEL MAKEOVERRIDES
cases_dir="$RCAN_ROOT/tools/testing/rcan/tests/misuse"
CHECK_DETAIL_LINES=40

kbuild=$(RCAN_KERNEL=release bash "$RCAN_ROOT/tools/testing/rcan/build-kernel.sh") || {
	check "release kernel for the misuse cases (build-kernel.sh)" 1
	check_summary
	exit 1
}

work=$(mktemp -d "${TMPDIR:-/tmp}/rcan-misuse.XXXXXX")
trap 'rm -rf "$work"' EXIT

# A private copy of what a module's crate includes (the glue, rcan_core)
# with bindings made for the release kernel, so the stage neither reads
# nor writes the checkout's generated bindings, which a build of the
# other kernel may be rewriting meanwhile.
mkdir -p "$work/src/rust/bindings" "$work/src/net/can"
cp -r "$RCAN_ROOT/rust/glue" "$work/src/rust/glue"
cp -r "$RCAN_ROOT/net/can/core" "$work/src/net/can/core"
cp "$RCAN_ROOT/net/can/rcan_core.rs" "$work/src/net/can/"
if ! out=$(bash "$RCAN_ROOT/rust/bindings/gen-bindings.sh" "$kbuild" \
	"$work/src/rust/bindings/bindings_generated.rs" 2>&1); then
	check "bindings for the misuse cases (gen-bindings.sh)" 1 "$out"
	check_summary
	exit 1
fi

# The rustc command line Kbuild uses for an out-of-tree module's Rust
# object, asked of Kbuild itself (a one-object module whose rule prints
# it instead of compiling), so the cases follow the kernel's flags.
mkdir -p "$work/probe"
cat > "$work/probe/Kbuild" <<'KBUILD'
obj-m := probe.o
$(obj)/probe.o: FORCE
	@printf '%s\n' '$(call escsq,$(rust_common_cmd))' > $(obj)/rustc-cmd
KBUILD
: > "$work/probe/probe.rs"
if ! out=$(make -s -C "$kbuild" M="$work/probe" LLVM=1 probe.o 2>&1) ||
	! grep -q -- '--extern kernel' "$work/probe/rustc-cmd" 2>/dev/null; then
	check "Kbuild's rustc command line for out-of-tree modules" 1 "$out"
	check_summary
	exit 1
fi
rustc_cmd=$(cat "$work/probe/rustc-cmd")
# The kernel's make exports this for its nightly-only flags.
export RUSTC_BOOTSTRAP=1

# compile CASE: type-checks misuse case CASE in a crate of its own;
# rustc's output in $work/NAME.log, its exit status returned.
compile() {
	local f=$1 name d
	name=$(basename "$f" .rs)
	d="$work/$name"
	mkdir -p "$d"
	cat > "$d/root.rs" <<ROOT
//! Crate root of misuse case $name (tools/testing/rcan/tests/misuse.sh):
//! what a module's root includes, and the case as a safe module beside it.
const __LOG_PREFIX: &[u8] = b"rcan_misuse\\0";
#[path = "$work/src/rust/glue/mod.rs"]
mod glue;
#[path = "$work/src/net/can/rcan_core.rs"]
mod rcan_core;
#[path = "$f"]
#[forbid(unsafe_code)]
mod case;
ROOT
	# Kbuild's output options point into the probe's directory: each
	# case writes into its own.
	(cd "$kbuild" && eval "${rustc_cmd//$work\/probe\//$d/} --emit=metadata=$d/lib.rmeta $d/root.rs") \
		> "$work/$name.log" 2>&1
}

# verdict CASE STATUS: empty if the compiler did what CASE expects, else why.
verdict() {
	local f=$1 rc=$2 name log expect code msg errs other
	name=$(basename "$f" .rs)
	log="$work/$name.log"
	expect=$(sed -n 's|^// expect: *||p' "$f" | head -n 1)
	code=${expect%% *}
	msg=${expect#"$code"}
	msg=${msg# }
	if [ -z "$expect" ]; then
		echo "no '// expect:' line in the case"
		return
	fi
	if [ "$code" = ok ]; then
		[ "$rc" = 0 ] || { echo "the control does not compile:"; grep -A8 '^error' "$log"; }
		return
	fi
	if [ "$rc" = 0 ]; then
		echo "compiled: the glue allows this misuse (expected $expect)"
		return
	fi
	# Every error is the expected one, and one says what the case says.
	errs=$(grep -E '^error(\[E[0-9]+\])?:' "$log" | grep -Ev '^error: aborting due to')
	other=$(printf '%s\n' "$errs" | grep -v "^error\[$code\]:")
	if [ -n "$other" ]; then
		echo "refused for another reason than $code:"
		grep -A8 -E '^error(\[E[0-9]+\])?:' "$log" | grep -v '^error: aborting'
		return
	fi
	if ! printf '%s\n' "$errs" | grep -qF -- "$msg"; then
		echo "error $code, but no message with \"$msg\":"
		printf '%s\n' "$errs"
		return
	fi
	# Every error is in the case, not in the glue it includes: the first
	# location after each error line names the case's file.
	if awk -v f="$f" '
		/^error\[E[0-9]+\]:/ { want = 1; next }
		want && /^ *--> / { if (index($0, "--> " f ":") == 0) bad = 1; want = 0 }
		END { exit !bad }' "$log"; then
		echo "error $code is not located in the case:"
		grep -A8 "^error\[$code\]" "$log"
	fi
}

t0=$(date +%s)
for f in "$cases_dir"/*.rs; do
	[ -e "$f" ] || continue
	compile "$f"
	rc=$?
	name=$(basename "$f" .rs)
	why=$(verdict "$f" "$rc")
	what=$(sed -n 's|^// expect: *||p' "$f" | head -n 1)
	if [ "${what%% *}" = ok ]; then
		check "misuse/$name.rs: the control compiles" "$([ -z "$why" ]; echo $?)" "$why"
	else
		check "misuse/$name.rs: refused with ${what%% *}" "$([ -z "$why" ]; echo $?)" "$why"
	fi
done

# The source check, first on a planted tree: each `bad_*` function below
# must be listed, none of the `good_*` ones.
rawptr="$RCAN_ROOT/tools/testing/rcan/rawptr-fns.sh"
mkdir -p "$work/planted/rust/glue/sub"
cat > "$work/planted/rust/glue/a.rs" <<'RS'
type Raw = *mut u8;
pub(crate) fn bad_mut(p: *mut u8) {}
fn bad_const<T>(x: u32,
    p: *const T) -> u32 { x }
pub(crate) extern "C" fn bad_entry(sk: *mut bindings::sock) {}
fn bad_nonnull(p: NonNull<u8>) {}
fn bad_alias(p: Raw) {}
fn bad_in_tuple(p: (usize, *mut u8)) {}
unsafe extern "C" {
    safe fn bad_foreign(p: *mut u8);
}
// fn good_comment(p: *mut u8) {}
/// fn good_doc(p: *mut u8) {}
pub(crate) unsafe fn good_unsafe(p: *mut u8) {}
unsafe extern "C" fn good_entry(sk: *mut bindings::sock) {}
fn good_fnptr(f: unsafe extern "C" fn(*mut u8) -> *mut u8, n: usize) {}
fn good_closure(f: impl FnMut(*mut u8)) {}
fn good_returns(&self) -> *mut u8 { self.0 }
extern "C" {
    fn good_foreign(p: *mut u8);
}
fn good_string() -> &'static str { "fn x(p: *mut u8) // not code" }
RS
cat > "$work/planted/rust/glue/sub/b.rs" <<'RS'
impl X {
    pub(in crate::glue) fn bad_method(&self, p: *const u8) -> bool { true }
    const unsafe fn good_const_unsafe(p: *const u8) {}
}
RS
got=$(bash "$rawptr" "$work/planted" 2>&1 | sed 's/^[^ ]* //' | sort | tr '\n' ' ')
want="bad_alias bad_const bad_entry bad_foreign (safe foreign fn) bad_in_tuple bad_method bad_mut bad_nonnull "
check "rawptr-fns.sh finds the planted safe functions taking raw pointers, and only those" \
	"$([ "$got" = "$want" ]; echo $?)" "found: $got
wanted: $want"

safe_ptr_fns=$(bash "$rawptr" "$RCAN_ROOT" 2>&1)
check "no safe function in rust/glue/ takes a raw pointer (rawptr-fns.sh)" \
	"$([ -z "$safe_ptr_fns" ]; echo $?)" "$safe_ptr_fns"

echo "misuse: $(( $(date +%s) - t0 )) s for the cases and the source check"
check_summary
[ "$failed" = 0 ]

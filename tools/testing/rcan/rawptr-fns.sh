#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Lists every safe function in ROOT/rust/glue/ (subfolders included) that
# takes a raw pointer, one "file:line: name" a line; prints nothing when
# there is none. Used by tests/misuse.sh (issue 39: "no safe function in
# rust/glue/ takes a raw pointer": a safe function that dereferences a
# pointer it is given is a precondition in a comment, not in a type; one
# that only stores or compares it is counted too, since the check cannot
# tell the two apart and the glue does without either).
#
# Text-level, not a parser. It sees: every `fn` item, method or trait
# method whose qualifiers lack `unsafe` (signatures may span lines),
# with a parameter whose type contains `*const`, `*mut`, `NonNull<` or a
# name the glue aliases to a raw pointer (`type X = *mut ...`); and `safe
# fn` declarations in `unsafe extern` blocks. It skips comments,
# declarations in `extern "C" { }` blocks (foreign functions, unsafe to
# call), and pointers that are only the parameters or result of a
# function-pointer or closure type (`unsafe extern "C" fn(*mut sock)`,
# `impl FnMut(*mut T)`): such a parameter is a function, not a pointer.
# It does not see: pointers behind type aliases of other crates
# (`bindings::`), inside structs passed by value, in generic parameters
# instantiated with a pointer, in closures' own parameters, or in
# functions that a macro of another crate (`module!`) generates.
#
# Usage: rawptr-fns.sh ROOT
set -euo pipefail
root=${1:?usage: rawptr-fns.sh ROOT}
cd "$root"
[ -d rust/glue ] || { echo "rawptr-fns.sh: no rust/glue in $root" >&2; exit 2; }
find rust/glue -name '*.rs' -print0 | sort -z | xargs -0 -r perl -0777 -ne '
	my $src = $_;
	# Balanced parentheses, up to any depth.
	my $par; $par = qr/\((?:[^()]++|(??{$par}))*\)/;
	my $brace; $brace = qr/\{(?:[^{}]++|(??{$brace}))*\}/;
	# Comments become blanks of the same lines (line numbers kept);
	# strings are kept whole so that "//" inside one is not a comment.
	$src =~ s{("(?:[^"\\]|\\.)*")|(//[^\n]*)|(/\*.*?\*/)}{
		defined $1 ? $1 : do { my $c = defined $2 ? $2 : $3; $c =~ s/[^\n]/ /g; $c } }gse;
	# Raw-pointer aliases of the glue.
	my @alias;
	while ($src =~ /\btype\s+(\w+)\s*(?:<[^=]*>)?\s*=\s*\*\s*(?:const|mut)\b/g) { push @alias, $1; }
	my $aliases = @alias ? join("|", @alias) : "(?!)";
	my $line_of = sub { 1 + (() = substr($src, 0, $_[0]) =~ /\n/g) };
	# `safe fn` in an `unsafe extern` block is safe to call.
	while ($src =~ /\bsafe\s+fn\s+(\w+)\s*($par)/g) {
		my ($at, $fn, $args) = ($-[0], $1, $2);
		print "$ARGV:", $line_of->($at), ": $fn (safe foreign fn)\n"
			if $args =~ /\*\s*(?:const|mut)\b|\bNonNull\s*<|\b(?:$aliases)\b/;
	}
	# Foreign blocks: their functions are unsafe to call.
	$src =~ s{\bextern\s+"C"\s*($brace)}{ my $b = $1; $b =~ s/[^\n]/ /g; $b }ge;
	while ($src =~ /(^|[;{}\n])([ \t]*(?:#\[[^\]]*\][ \t]*)*(?:pub(?:\s*\([^)]*\))?\s+)?(?:(?:const|async|default|unsafe|extern\s+"[^"]*")\s+)*)fn\s+(\w+)\s*(<(?:[^<>]++|<(?:[^<>]++|<[^<>]*>)*>)*>)?\s*($par)/g) {
		my ($at, $pre, $fn, $args) = ($-[3], $2, $3, $5);
		next if $pre =~ /\bunsafe\b/;
		# Function-pointer and closure types among the parameters:
		# their own parameters and results are not ours.
		1 while $args =~ s/\b(?:unsafe\s+)?(?:extern\s+"[^"]*"\s+)?fn\s*$par(?:\s*->\s*[^,()]+)?/FNPTR/g;
		1 while $args =~ s/\bFn(?:Mut|Once)?\s*$par(?:\s*->\s*[^,()]+)?/CLOSURE/g;
		next unless $args =~ /\*\s*(?:const|mut)\b|\bNonNull\s*<|\b(?:$aliases)\b/;
		print "$ARGV:", $line_of->($at), ": $fn\n";
	}'

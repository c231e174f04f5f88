# SPDX-License-Identifier: GPL-2.0
# Sourced by the shell test stages (frontdoor.sh, unsafe.sh, dkms.sh): counts
# results as make check's tally expects them.
#
# check NAME STATUS [DETAIL]: counts one test, passed if STATUS is 0; a
# failure shows DETAIL (its first $CHECK_DETAIL_LINES lines, default 12).
# check_summary: the closing "N passed, M failed" line.
passed=0
failed=0
check() {
	if [ "$2" = 0 ]; then
		echo "ok - $1"
		passed=$((passed + 1))
	else
		echo "not ok - $1"
		[ -z "${3:-}" ] ||
			printf '%s\n' "$3" | head -n "${CHECK_DETAIL_LINES:-12}" | sed 's/^/#   /'
		failed=$((failed + 1))
	fi
}
check_summary() {
	echo "$passed passed, $failed failed"
}

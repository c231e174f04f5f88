# SPDX-License-Identifier: GPL-2.0
# Counts SJA1000 register accesses per benchmark phase in a QEMU trace log
# (memory_region_ops_read/write events). Input: the phase lines of
# rcan-bench-sja (file 1: "SJA-MARKERS <start> <end>", "SJA-PHASE n stack
# round frames seconds"), then the trace (file 2). A phase is the span
# between a write of <start> and of <end> to QEMU's pci-conf-idx port;
# every access to a kvaser_pci-* region inside it counts. Prints one line
# per phase (accesses, per frame, frames/s) and per stack (accesses per
# frame, median of the phases' frames/s: the host's load makes single
# phases slow at random).
FNR == NR {
	if ($1 == "SJA-MARKERS") { s = $2; e = $3 }
	if ($1 == "SJA-PHASE") {
		stack[$2] = $3; frames[$2] = $5; secs[$2] = $6
		if ($2 + 1 > nph) nph = $2 + 1
	}
	next
}
BEGIN { ph = -1; inph = 0 }
/name .pci-conf-idx./ && /memory_region_ops_write/ {
	for (i = 1; i <= NF; i++) if ($i == "value") v = $(i + 1)
	if (v == s) { ph++; inph = 1 } else if (v == e) { inph = 0 }
	next
}
inph && /name .kvaser_pci-/ {
	n[ph]++
	if ($1 == "memory_region_ops_read") r[ph]++
}
END {
	printf "%-6s %-9s %6s %9s %10s %8s %10s\n", "phase", "stack", "frames", "accesses", "per frame", "reads", "frames/s"
	for (p = 0; p < nph; p++) {
		f = frames[p]; if (f == 0) continue
		printf "%-6d %-9s %6d %9d %10.2f %8.2f %10.0f\n", p, stack[p], f, n[p], n[p] / f, r[p] / f, f / secs[p]
		k = stack[p]
		ta[k] += n[p]; tf[k] += f
		rate[k, ++nr[k]] = f / secs[p]
	}
	print ""
	printf "%-9s %8s %10s %16s\n", "stack", "frames", "acc/frame", "frames/s median"
	for (k in tf) {
		med[k] = median(k)
		printf "%-9s %8d %10.2f %16.0f\n", k, tf[k], ta[k] / tf[k], med[k]
	}
	if (tf["ours"] && tf["mainline"])
		printf "ours/mainline: accesses per frame %.3f, throughput (medians) %.3f\n",
			(ta["ours"] / tf["ours"]) / (ta["mainline"] / tf["mainline"]),
			med["ours"] / med["mainline"]
}

# Median of the phase rates of stack k (insertion sort; a handful).
function median(k,    i, j, t, a, m) {
	m = nr[k]
	for (i = 1; i <= m; i++) a[i] = rate[k, i]
	for (i = 2; i <= m; i++) {
		t = a[i]
		for (j = i - 1; j >= 1 && a[j] > t; j--) a[j + 1] = a[j]
		a[j + 1] = t
	}
	return m % 2 ? a[(m + 1) / 2] : (a[m / 2] + a[m / 2 + 1]) / 2
}

# SPDX-License-Identifier: GPL-2.0
# Counts a card's register accesses per benchmark phase in a QEMU trace log
# (memory_region_ops_read/write events): the SJA1000 section of bench.sh
# (rcan-bench-sja, kvaser_pci regions; the defaults) and its CTU CAN FD
# section (rcan-bench-ctu: -v tag=CTU -v region=ctucan). Input: the phase
# lines of the program (file 1: "<tag>-MARKERS <start> <end>", "<tag>-PHASE
# n stack round frames seconds [shape [kernel-CPU-ns-per-frame]]"), then
# the trace (file 2). A phase is the span between a write of <start> and of
# <end> to QEMU's pci-conf-idx port; every access to a region whose name
# starts with <region> inside it counts. Prints one line per phase
# (accesses, per frame, frames/s) and per stack and shape (accesses per
# frame, median of the phases' frames/s and kernel CPU per frame: the
# host's load makes single phases slow at random). With -v regs=1 also
# accesses per frame by stack, direction and address (region name and
# address as in the trace), for telling where two drivers differ.
BEGIN {
	if (tag == "") tag = "SJA"
	if (region == "") region = "kvaser_pci-"
	ph = -1; inph = 0
}
FNR == NR {
	if ($1 == tag "-MARKERS") { s = $2; e = $3 }
	if ($1 == tag "-PHASE") {
		key[$2] = $3 ($7 != "" ? " " $7 : ""); frames[$2] = $5; secs[$2] = $6
		cpu[$2] = $8
		if ($2 + 1 > nph) nph = $2 + 1
	}
	if ($1 == tag "-FAILED") { k = $3 " " $5; sub(/:$/, "", k); failed[k]++ }
	next
}
/name .pci-conf-idx./ && /memory_region_ops_write/ {
	for (i = 1; i <= NF; i++) if ($i == "value") v = $(i + 1)
	if (v == s) { ph++; inph = 1 } else if (v == e) { inph = 0 }
	next
}
inph && index($0, "name '" region) {
	n[ph]++
	if ($1 == "memory_region_ops_read") r[ph]++
	if (regs) {
		for (i = 1; i <= NF; i++) if ($i == "addr") ad = $(i + 1)
		nm = substr($0, index($0, "name '") + 6); sub(/'.*/, "", nm)
		acc[ph, ($1 == "memory_region_ops_read" ? "R" : "W") " " nm " " ad]++
	}
}
END {
	printf "%-6s %-18s %6s %9s %10s %8s %10s\n", "phase", "stack", "frames", "accesses", "per frame", "reads", "frames/s"
	for (p = 0; p < nph; p++) {
		f = frames[p]; if (f == 0) continue
		printf "%-6d %-18s %6d %9d %10.2f %8.2f %10.0f\n", p, key[p], f, n[p], n[p] / f, r[p] / f, f / secs[p]
		k = key[p]
		ta[k] += n[p]; tf[k] += f
		rate[k, ++nr[k]] = f / secs[p]
		if (cpu[p] != "") { cpuv[k, ++nc[k]] = cpu[p] }
	}
	print ""
	printf "%-18s %8s %10s %16s %14s\n", "stack", "frames", "acc/frame", "frames/s median", "CPU ns/frame"
	for (k in tf) {
		med[k] = median(rate, k, nr[k])
		mc[k] = nc[k] ? median(cpuv, k, nc[k]) : 0
		printf "%-18s %8d %10.2f %16.0f %14s\n", k, tf[k], ta[k] / tf[k], med[k], nc[k] ? sprintf("%.0f", mc[k]) : "-"
	}
	for (k in failed)
		printf "%s: %d phase(s) failed (frames lost, out of order or not sent; not counted above)\n", k, failed[k]
	# Ratios ours/mainline, for each shape both stacks have.
	for (k in tf) {
		if (k !~ /^ours/) continue
		m = k; sub(/^ours/, "mainline", m)
		if (!(m in tf)) continue
		sh = k; sub(/^ours ?/, "", sh)
		printf "ours/mainline%s: accesses per frame %s, throughput (medians) %.3f", sh != "" ? " (" sh ")" : "",
			ta[m] ? sprintf("%.3f", (ta[k] / tf[k]) / (ta[m] / tf[m])) : "-", med[k] / med[m]
		if (nc[k] && nc[m] && mc[m] > 0) printf ", kernel CPU per frame (medians) %.3f", mc[k] / mc[m]
		printf "\n"
	}
	if (regs) {
		print ""
		printf "%-18s %-3s %-24s %-12s %9s\n", "stack", "r/w", "region", "address", "per frame"
		for (x in acc) {
			split(x, q, SUBSEP)
			if (frames[q[1]] == 0) continue
			split(q[2], w, " ")
			per[key[q[1]] SUBSEP w[1] SUBSEP w[2] SUBSEP w[3]] += acc[x]
		}
		for (x in per) {
			split(x, w, SUBSEP)
			printf "%-18s %-3s %-24s %-12s %9.2f\n", w[1], w[2], w[3], w[4], per[x] / tf[w[1]]
		}
	}
}

# Median of a[k, 1..m] (insertion sort; a handful).
function median(a, k, m,    i, j, t, b) {
	for (i = 1; i <= m; i++) b[i] = a[k, i]
	for (i = 2; i <= m; i++) {
		t = b[i]
		for (j = i - 1; j >= 1 && b[j] > t; j--) b[j + 1] = b[j]
		b[j + 1] = t
	}
	return m % 2 ? b[(m + 1) / 2] : (b[m / 2] + b[m / 2 + 1]) / 2
}

#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-2.0
"""Host side of prof-bindclose.sh: splits the samples of each stack's run
by phase (from the workload's marks) and by where they landed (the leaf
function), and prints, per phase, instructions per call by category.

usage: prof-split.py OUT [PERIOD [TOP]]

Under RCAN_KVM=icount one guest nanosecond is one instruction, so a sample
every PERIOD ns is a sample every PERIOD instructions; a category's share
of a phase's samples times the phase's length (from marks-noperf-*, the
same workload without perf) per call is its instructions per call. Only
the leaf is used: call chains through the Rust modules do not unwind.
Idle samples (the idle loop of an idle CPU) are left out; everything else
on either CPU during the phase counts (softirq and RCU work landing in the
phase is the phase's cost, as the bench's per-call times see it).
"""
import collections
import glob
import gzip
import os
import re
import sys

out = sys.argv[1]
period = int(sys.argv[2]) if len(sys.argv) > 2 else 20000
top = int(sys.argv[3]) if len(sys.argv) > 3 else 12

IDLE = {"default_idle", "pv_native_safe_halt", "native_safe_halt", "acpi_idle_do_entry",
        "arch_cpu_idle", "do_idle", "cpuidle_idle_call", "default_idle_call", "mwait_idle",
        "intel_idle", "cpu_idle_poll", "poll_idle"}
OUR_MODS = {"rcan_pf", "rcan_raw", "rcan_can", "rcan_loop"}
ML_MODS = {"can", "can_raw", "vcan", "can_dev"}
RULES = [  # (category, regexp on a kernel symbol), first match wins
    ("alloc/free (slab, pages)", r"^(kmem_cache_|__kmem_cache|kmalloc|__kmalloc|kfree|__kfree|slab_|__slab|___slab|"
     r"kmalloc_|krealloc|kvfree|kvmalloc|__kvmalloc|memcg|obj_cgroup|mod_objcg|refill_obj_stock|"
     r"__memcg|alloc_pages|__alloc_pages|get_page_from_freelist|free_pcppages|free_unref|__free_pages|"
     r"clear_page|rmqueue|__rmqueue|setup_object|shuffle_freelist|allocate_slab|new_slab|"
     r"put_cpu_partial|deactivate_slab|get_partial|__put_partials|discard_slab|init_object|sk_prot_alloc|sk_prot_free)"),
    ("RCU (call_rcu, callbacks, GP)", r"^(call_rcu|__call_rcu|rcu_|__rcu|kfree_rcu|note_gp|rcu_core|"
     r"invoke_rcu|srcu|synchronize_rcu|kvfree_call_rcu|__sk_destruct|sk_destruct|__sk_free)"),
    ("softirq/irq/timer entry and exit", r"^(handle_softirqs|__do_softirq|irq_exit|__irq_exit|do_softirq|"
     r"__local_bh_enable|_raw_spin_unlock_irqrestore|_raw_spin_unlock_irq|sysvec_|asm_sysvec|"
     r"hrtimer_|__hrtimer|tick_|timekeeping|update_process_times|run_timer|__run_timer|scheduler_tick|"
     r"sched_tick|irqentry|common_interrupt|asm_common)"),
    ("locks (mutex, spin, RTNL, socket lock)", r"^(mutex_|__mutex|_raw_spin|__raw_spin|rtnl_|__rtnl|lock_sock|"
     r"release_sock|__lock_sock|__release_sock|_raw_read|_raw_write|down_|up_read|up_write|queued_spin)"),
    ("syscall entry/exit", r"^(entry_SYSCALL|do_syscall|syscall_|__x64_sys|x64_sys_call|"
     r"exit_to_user|arch_exit|syscall_exit|__sys_|fpregs|restore_fpregs|switch_fpu)"),
]
RULES = [(c, re.compile(r)) for c, r in RULES]
GENERIC = "generic kernel (VFS, socket, net core, sched, other)"


def demangle(sym):
    """A readable tail of a Rust v0 symbol (its last identifiers)."""
    if not sym.startswith("_R"):
        return sym
    parts, i = [], 0
    for m in re.finditer(r"(\d+)([A-Za-z_][A-Za-z0-9_]*)", sym):
        n = int(m.group(1))
        parts.append(m.group(2)[:n])
    keep = [p for p in parts if p not in ("glue", "can", "kernel", "core") and not p.endswith("_mod")]
    return "::".join(keep[-3:]) or sym


def category(sym, dso, stack):
    mod = dso.strip("[]") if dso.startswith("[") and dso != "[kernel.kallsyms]" else None
    if mod in OUR_MODS or mod in ML_MODS:
        if stack == "mainline":
            return f"CAN modules ({mod})"
        if not sym.startswith("_R"):
            return "ours: C helpers (*_c.c) and C-ABI entries"
        d = demangle(sym)
        if re.search(r"rx::|RxTable|rxtable|KeyEntry|Rcv|List|Nodes|Reg", d):
            return f"ours: receive table ({mod})"
        return f"ours: protocol/family code ({mod})"
    if dso not in ("[kernel.kallsyms]", "[unknown]") and not mod:
        return "user space"
    if sym.startswith("[unknown]") or not sym:
        return "user space" if not dso.startswith("[k") else GENERIC
    for c, r in RULES:
        if r.search(sym):
            return c
    return GENERIC


LINE = re.compile(r"^\s*(\S.*?)\s+\[(\d+)\]\s+(\d+)\.(\d+):\s+([0-9a-f]+)\s+(.*?)\s+\((.*)\)\s*$")


def load(tag):
    marks = {}
    for f, key in ((f"{out}/marks-{tag}.txt", "perf"), (f"{out}/marks-noperf-{tag}.txt", "noperf")):
        for l in open(f):
            p = l.split()
            if p and p[0] == "PHASE":
                marks.setdefault(key, []).append((p[1], int(p[2]), int(p[3]), int(p[4])))
    return marks


def lengths():
    """Per-call length of each phase of the runs without perf, every
    stack: under icount, instructions (the Python loop included; the
    null phases are that floor)."""
    n = int(os.environ.get("N", "10000"))
    tags = sorted((os.path.basename(f)[len("marks-noperf-"):-len(".txt")]
                   for f in glob.glob(f"{out}/marks-noperf-*.txt")), key=lambda t: int(t.split("-")[0]))
    print(f"== per call, instructions (median over rounds), runs without perf ==")
    cols = ["open", "bind", "nullbind", "close", "nullclose"]
    print(f"{'run':24s}" + "".join(f"{c:>10s}" for c in cols) + f"{'bind-null':>11s}{'close-null':>11s}{'b+c-null':>10s}")
    for tag in tags:
        per = collections.defaultdict(list)
        for l in open(f"{out}/marks-noperf-{tag}.txt"):
            p = l.split()
            if p and p[0] == "PHASE":
                per[p[1]].append((int(p[4]) - int(p[3])) / n)
        med = {k: sorted(v)[len(v) // 2] for k, v in per.items()}
        row = "".join(f"{med.get(c, float('nan')):10.0f}" for c in cols)
        b = med["bind"] - med.get("nullbind", 0)
        c = med["close"] - med.get("nullclose", 0)
        print(f"{tag:24s}{row}{b:11.0f}{c:11.0f}{b + c:10.0f}")
    print()


def main():
    lengths()
    tags = sorted(os.path.basename(f)[len("script-"):-len(".txt.gz")] for f in glob.glob(f"{out}/script-*.txt.gz"))
    n = int(os.environ.get("N", "10000"))
    res = {}
    for tag in tags:
        stack = tag.split("-", 1)[1]
        marks = load(tag)
        phases = [(name, s, e) for name, _r, s, e in marks["perf"]]
        cnt = collections.defaultdict(collections.Counter)
        fn = collections.defaultdict(collections.Counter)
        for l in gzip.open(f"{out}/script-{tag}.txt.gz", "rt", errors="replace"):
            m = LINE.match(l)
            if not m:
                continue
            comm, _cpu, s, ns, _ip, sym, dso = m.groups()
            t = int(s) * 10**9 + int(ns.ljust(9, "0")[:9])
            ph = next((name for name, a, b in phases if a <= t < b), None)
            if ph is None:
                continue
            sym = re.sub(r"\+0x[0-9a-f]+$", "", sym)
            if sym in IDLE:
                continue
            c = category(sym, dso, stack)
            cnt[ph][c] += 1
            fn[ph][(c, demangle(sym) if c != "user space" else "(user space)")] += 1
        # per-call length of each phase without perf, instructions
        rounds = collections.Counter(name for name, *_ in marks["noperf"])
        length = collections.Counter()
        for name, _r, a, b in marks["noperf"]:
            length[name] += b - a
        rounds_perf = collections.Counter(name for name, *_ in marks["perf"])
        res[tag] = (stack, cnt, fn, {k: length[k] / rounds[k] / n for k in length}, rounds_perf)
    for ph in ("bind", "nullbind", "close", "nullclose", "after-close"):
        print(f"== {ph}: instructions per call (samples x {period} / calls; "
              f"phase length without perf in brackets) ==")
        cats = sorted({c for t in res for c in res[t][1][ph]})
        print(f"{'category':58s}" + "".join(f"{t:>16s}" for t in res))
        for c in cats:
            row = ""
            for t in res:
                _st, cnt, _fn, _len, rp = res[t]
                row += f"{cnt[ph][c] * period / (rp[ph] * n):16.0f}"
            print(f"{c:58s}{row}")
        tot = "".join(f"{sum(res[t][1][ph].values()) * period / (res[t][4][ph] * n):16.0f}" for t in res)
        print(f"{'total (perf samples)':58s}{tot}")
        print(f"{'phase length without perf, per call':58s}" + "".join(f"{res[t][3][ph]:16.0f}" for t in res))
        for t in res:
            print(f"  top leaves, {t}:")
            for (c, f), k in res[t][2][ph].most_common(top):
                print(f"    {k * period / (res[t][4][ph] * n):8.0f}  {f}  [{c}]")
        print()


main()

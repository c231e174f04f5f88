#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-2.0
"""Host side of prof-frame.sh, per symbol: the leaf samples of each
stack's run in one phase (default ``frame``, minus the same symbol's in
``null``), as instructions per frame (samples x PERIOD / frames), for
every function of the stack's own modules (ours: rcan_pf, rcan_can,
rcan_raw, rcan_loop; mainline: can, can_raw, vcan, can_dev), and, with
-k, for the kernel's functions, side by side for every stack in OUT.
With -o SYM, the samples of module functions whose demangled name
contains SYM, by offset, to read against ``objdump -d`` of the .ko.

Scaling. Under RCAN_KVM=icount a sample comes every PERIOD guest
instructions, but the sampling handler's own instructions (interrupts
off) never receive a sample, so samples x PERIOD overstates every
function by the same factor f = (handler + workload) / workload; and the
profiled run adds its random jitter loop in user space (the same in
both phases). So f is measured per stack from the run itself: the busy
samples of (frame - null) x PERIOD / frames, over (frame - null) of the
same stack's run without perf (marks-noperf-*), in which the jitter
cancels. The "instr" column is the raw figure / f; "raw" is samples x
PERIOD / frames. (prof-frame-split.py scales by the phase lengths
instead, which also divides out the jitter loop: its figures are lower
by the ratio of the two, about 0.88 in the 2026-11-28 boot.)

usage: prof-frame-syms.py OUT [-p PERIOD] [-n N] [-k TOP] [-o SYM]...
"""
import argparse
import collections
import glob
import gzip
import os
import re
import subprocess

ap = argparse.ArgumentParser()
ap.add_argument("out")
ap.add_argument("-p", "--period", type=int, default=9973)
ap.add_argument("-n", type=int, default=int(os.environ.get("N", "20480")))
ap.add_argument("-k", "--kernel-top", type=int, default=0)
ap.add_argument("-o", "--offsets", action="append", default=[])
ap.add_argument("--phase", default="frame")
args = ap.parse_args()

MODS = {"rcan_pf", "rcan_raw", "rcan_can", "rcan_loop", "can", "can_raw", "vcan", "can_dev"}
LINE = re.compile(r"^\s*(\S.*?)\s+(\d+)\s+\[(\d+)\]\s+(\d+)\.(\d+):\s+([0-9a-f]+)\s+(.*?)\s+\((.*)\)\s*$")
IDLE = re.compile(r"idle|safe_halt")


def demangle_all(syms):
    syms = sorted(s for s in syms if s.startswith("_R"))
    if not syms:
        return {}
    res = subprocess.run(["c++filt"], input="\n".join(syms), capture_output=True, text=True).stdout
    out = {}
    for s, d in zip(syms, res.splitlines()):
        d = re.sub(r"\[[0-9a-f]{1,16}\]", "", d)
        d = re.sub(r"\b\w+_mod::(glue::)?", "", d)
        out[s] = d
    return out


def marks(f):
    return [(p[1], int(p[3]), int(p[4])) for p in (line.split() for line in open(f))
            if p and p[0] == "PHASE"]


def load(tag):
    ph = marks(f"{args.out}/marks-{tag}.txt")
    rounds = collections.Counter(name for name, *_ in ph)
    per = collections.defaultdict(collections.Counter)  # phase -> (dso, sym) -> samples
    offs = collections.defaultdict(collections.Counter)  # (dso, sym) -> off -> samples (phase)
    for line in gzip.open(f"{args.out}/script-{tag}.txt.gz", "rt", errors="replace"):
        m = LINE.match(line)
        if not m:
            continue
        comm, _tid, _cpu, s, ns, _ip, sym, dso = m.groups()
        if comm == "perf":
            continue
        t = int(s) * 10**9 + int(ns.ljust(9, "0")[:9])
        name = next((n for n, a, b in ph if a <= t < b), None)
        if name is None:
            continue
        mo = re.match(r"^(.*)\+0x([0-9a-f]+)$", sym)
        base, off = (mo.group(1), int(mo.group(2), 16)) if mo else (sym, 0)
        if IDLE.search(base):
            continue
        mod = dso.strip("[]") if dso.startswith("[") else "user"
        if mod == "kernel.kallsyms":
            mod = "kernel"
        if mod not in MODS and mod != "kernel":
            mod, base = "user", "(user space)"
        per[name][(mod, base)] += 1
        if name == args.phase:
            offs[(mod, base)][off] += 1
    return per, rounds, offs


def main():
    tags = sorted((os.path.basename(f)[len("script-"):-len(".txt.gz")]
                   for f in glob.glob(f"{args.out}/script-*.txt.gz")),
                  key=lambda x: int(x.split("-")[0]))
    data = {t: load(t) for t in tags}
    allsyms = {s for t in data for ph in data[t][0].values() for (_m, s) in ph}
    dm = demangle_all(allsyms)

    def per_frame(t, ph, key):
        per, rounds, _ = data[t]
        return per[ph][key] * args.period / (rounds[ph] * args.n) if rounds[ph] else 0.0

    def own(t, key):
        return per_frame(t, args.phase, key) - per_frame(t, "null", key)

    def noperf(t):
        per = collections.defaultdict(list)
        for name, a, b in marks(f"{args.out}/marks-noperf-{t}.txt"):
            per[name].append((b - a) / args.n)
        return {k: sorted(v)[len(v) // 2] for k, v in per.items()}

    scale = {}
    for t in tags:
        per, rounds, _ = data[t]
        busy = {ph: sum(per[ph].values()) * args.period / (rounds[ph] * args.n) for ph in per}
        npf = noperf(t)
        scale[t] = (busy[args.phase] - busy["null"]) / (npf[args.phase] - npf["null"])
        print(f"{t}: {args.phase} - null: {busy[args.phase] - busy['null']:.0f} under perf "
              f"(samples x period), {npf[args.phase] - npf['null']:.0f} without perf: "
              f"f = {scale[t]:.3f}")
    print()
    for t in tags:
        per = data[t][0]
        keys = {k for ph in (args.phase, "null") for k in per[ph] if k[0] not in ("kernel", "user")}
        rows = sorted(keys, key=lambda k: -own(t, k))
        print(f"== {t}: module functions, instructions per frame ({args.phase} - null) ==")
        print(f"{'instr':>8s}{'raw':>8s}  module     function")
        tot = collections.Counter()
        for k in rows:
            v = own(t, k)
            tot[k[0]] += v
            print(f"{v / scale[t]:8.1f}{v:8.1f}  {k[0]:10s} {dm.get(k[1], k[1])}")
        for mod, v in sorted(tot.items()):
            print(f"{v / scale[t]:8.1f}{v:8.1f}  {mod:10s} (module total)")
        v = sum(tot.values())
        print(f"{v / scale[t]:8.1f}{v:8.1f}  (all modules)")
        print(f"   ({args.phase}: {sum(per[args.phase].values())} busy samples in "
              f"{data[t][1][args.phase]} rounds)\n")
    if args.kernel_top:
        keys = {k for t in tags for ph in (args.phase, "null") for k in data[t][0][ph]
                if k[0] in ("kernel", "user")}
        print(f"== kernel leaves, instructions per frame ({args.phase} - null, / f), "
              f"by largest |difference| ==")
        print(f"{'':8s}" + "".join(f"{t:>14s}" for t in tags))
        rows = sorted(keys, key=lambda k: -max(abs(own(a, k) - own(b, k)) for a in tags for b in tags)
                      - 0.001 * max(abs(own(a, k)) for a in tags))
        for k in rows[:args.kernel_top]:
            print(f"{'':8s}" + "".join(f"{own(t, k) / scale[t]:14.1f}" for t in tags) + f"  {k[1]}")
        print()
    for pat in args.offsets:
        for t in tags:
            offs = data[t][2]
            for k, c in offs.items():
                if k[0] == "user" or pat not in dm.get(k[1], k[1]) or (k[0] == "kernel" and pat != k[1]):
                    continue
                n = data[t][1][args.phase] * args.n
                print(f"== {t}: {dm.get(k[1], k[1])} ({k[0]}) by offset, "
                      f"instructions per frame ({args.phase}) ==")
                for off, v in sorted(c.items()):
                    print(f"  +0x{off:04x} {v * args.period / n / scale[t]:7.1f}")
                print()


main()

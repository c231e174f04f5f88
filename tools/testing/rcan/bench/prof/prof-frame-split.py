#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-2.0
"""Host side of prof-frame.sh: splits the samples of each stack's run by
phase (from the workload's marks), by CPU, and by where they landed (the
leaf function), and prints, per phase, instructions per frame by
category.

usage: prof-frame-split.py OUT [PERIOD [TOP]]    (env N: frames per round)

Under RCAN_KVM=icount one guest nanosecond is one instruction, so a sample
every PERIOD ns is a sample every PERIOD instructions; a category's
samples times PERIOD per frame is its instructions per frame. Only the
leaf is used: call chains through the Rust modules do not unwind. Idle
samples (the idle loop of an idle CPU) and those of the perf tool itself
(which writes its samples on the other CPU) are left out; everything else
on either CPU during the phase counts (softirq and RCU work landing in the
phase is the phase's cost). The first table gives the phases' lengths
without perf: under icount these are instructions too, but both vCPUs
advance one clock, so they are not the sum of both CPUs' work.
"""
import collections
import glob
import gzip
import os
import re
import sys

out = sys.argv[1]
period = int(sys.argv[2]) if len(sys.argv) > 2 else 9973
top = int(sys.argv[3]) if len(sys.argv) > 3 else 25
n = int(os.environ.get("N", "20480"))

IDLE = {"default_idle", "pv_native_safe_halt", "native_safe_halt", "acpi_idle_do_entry",
        "arch_cpu_idle", "do_idle", "cpuidle_idle_call", "default_idle_call", "mwait_idle",
        "intel_idle", "cpu_idle_poll", "poll_idle", "acpi_safe_halt", "acpi_idle_enter",
        "cpuidle_enter_state", "arch_cpu_idle_enter", "arch_cpu_idle_exit"}
OUR_MODS = {"rcan_pf", "rcan_raw", "rcan_can", "rcan_loop"}
ML_MODS = {"can", "can_raw", "vcan", "can_dev"}

# (category, regexp on a kernel symbol), first match wins. The order
# matters where names overlap (skb_* copies before skb_* frees, ...).
RULES = [
    ("perf sampling itself", r"^(perf_|__perf|x86_pmu|intel_pmu|native_sched_clock|sched_clock|"
     r"local_clock|cpu_clock_event|task_clock)"),
    ("syscall entry/exit", r"^(entry_SYSCALL|do_syscall|syscall_|__x64_sys|x64_sys_call|"
     r"exit_to_user|arch_exit|fpregs|restore_fpregs|switch_fpu|__rseq|rseq_|fpu__|"
     r"syscall_exit|irqentry_exit_to_user)"),
    ("socket layer (fd, sendto/recvfrom, iov, LSM)", r"^(__sys_sendto|__sys_recvfrom|__sys_sendmsg|"
     r"__sys_recvmsg|___sys|sock_sendmsg|sock_recvmsg|__sock_sendmsg|sock_sendmsg_nosec|"
     r"sock_recvmsg_nosec|sockfd_lookup|__fdget|fdget|__fget|fget|fput|__fput|import_ubuf|"
     r"import_single_range|import_iovec|move_addr_to|security_|selinux_|apparmor_|bpf_lsm|"
     r"__check_object_size|check_heap_object|__virt_addr_valid|check_stack_object|"
     r"__check_heap_object|sock_from_file|__sock_release|iov_iter_init)"),
    ("copy (user <-> skb)", r"^(skb_copy_datagram|__skb_datagram_iter|simple_copy_to_iter|"
     r"_copy_to_iter|_copy_from_iter|copy_user|rep_movs|copy_to_user|copy_from_user|"
     r"_copy_to_user|_copy_from_user|memcpy|__memcpy|memmove|memset|__memset|"
     r"skb_put|skb_copy_bits|csum_and_copy|memcpy_orig|memset_orig|clear_user|"
     r"memcpy_to_msg|memcpy_from_msg|copy_page)"),
    ("skb alloc/free (slab, skb, sock memory)", r"^(kmem_cache_|__kmem_cache|kmalloc|__kmalloc|kfree|"
     r"__kfree|slab_|__slab|___slab|kmalloc_|krealloc|kvfree|memcg|obj_cgroup|mod_objcg|"
     r"refill_obj_stock|__memcg|alloc_pages|__alloc_pages|get_page_from_freelist|free_pcp|"
     r"free_unref|__free_pages|clear_page|rmqueue|__rmqueue|setup_object|allocate_slab|new_slab|"
     r"put_cpu_partial|deactivate_slab|get_partial|__put_partials|discard_slab|init_object|"
     r"__alloc_skb|alloc_skb|__build_skb|build_skb|napi_alloc|__napi_alloc|kmalloc_reserve|"
     r"sock_alloc_send|alloc_skb_with_frags|skb_release|skb_free_head|kfree_skb|__kfree_skb|"
     r"consume_skb|sk_skb_reason_drop|__consume_stateless_skb|skb_attempt_defer|napi_consume_skb|"
     r"napi_skb_cache|__napi_kfree_skb|skb_clone|__skb_clone|__copy_skb_header|skb_headers_offset|"
     r"sock_wfree|sock_rfree|__sock_wfree|skb_set_owner|skb_orphan|sock_def_write_space|"
     r"sk_wmem|skb_free_datagram|__skb_ext|skb_dst|dst_release|sock_efree|can_skb)"),
    ("xmit (dev_queue_xmit, qdisc)", r"^(__dev_queue_xmit|dev_queue_xmit|dev_hard_start_xmit|"
     r"sch_direct_xmit|__qdisc_run|qdisc_|pfifo_fast|__dev_xmit|validate_xmit|netdev_core_pick_tx|"
     r"netdev_pick_tx|dev_qdisc|netif_skb_features|skb_network_protocol|dev_queue_xmit_nit|"
     r"netdev_start_xmit|xmit_one|skb_csum_hwoffload|netif_tx|__netif_schedule|net_tx_action|"
     r"dev_xmit_recursion|tcf_|sch_handle_egress|netdev_tx)"),
    ("netif_rx, backlog, NAPI, NET_RX softirq", r"^(netif_rx|__netif_rx|enqueue_to_backlog|"
     r"process_backlog|net_rx_action|__napi_poll|napi_|____napi|__napi|gro_|dev_gro|"
     r"__netif_receive|netif_receive|deliver_skb|deliver_ptype|__netif_receive_skb_core|"
     r"handle_softirqs|__do_softirq|do_softirq|__local_bh_enable|local_bh_enable|"
     r"irq_exit|__irq_exit|raise_softirq|__raise_softirq|rps_|get_rps|skb_defer_free|"
     r"eth_type|tcf_classify|sch_handle_ingress|netif_napi|busy_poll|napi_busy|"
     r"kick_defer|smp_call_function_single_async|generic_smp_call|flush_smp_call|"
     r"skb_pfmemalloc|__netif_receive_skb_one_core|netdev_rx)"),
    ("socket queue, wake-up, datagram receive", r"^(sock_queue_rcv_skb|__sock_queue_rcv_skb|"
     r"sk_filter|skb_queue_tail|__skb_recv_datagram|__skb_try_recv_datagram|skb_recv_datagram|"
     r"__skb_wait_for_more_packets|sock_def_readable|__wake_up|autoremove_wake_function|"
     r"receiver_wake_function|default_wake_function|__skb_try_recv_from_queue|"
     r"sock_recv_cmsgs|__sock_recv_cmsgs|__sock_recv_timestamp|__sock_recv_wifi|"
     r"sock_recv_timestamp|sock_rcvtimeo|prepare_to_wait|finish_wait|skb_queue_head|"
     r"skb_dequeue|sk_mem_|__sk_mem|sock_rmem|sk_rmem|ktime_get_real|ktime_get_with_offset|"
     r"sock_def_wakeup|datagram_poll|sk_data_ready|sk_wake_async|sock_wake_async|"
     r"wake_up_interruptible)"),
    ("RCU", r"^(call_rcu|__call_rcu|rcu_|__rcu|kfree_rcu|note_gp|invoke_rcu|srcu|"
     r"synchronize_rcu|kvfree_call_rcu)"),
    ("scheduler, context switch", r"^(schedule|__schedule|pick_next|try_to_wake_up|ttwu_|"
     r"enqueue_|dequeue_|update_curr|update_load|update_cfs|finish_task_switch|switch_mm|"
     r"__switch_to|psi_|set_next_entity|put_prev|check_preempt|resched_curr|sched_|"
     r"__update_load|reweight|place_entity|update_rq_clock|select_task_rq|wake_up_q|"
     r"raw_spin_rq|__enqueue|__dequeue|account_|cpuacct|cgroup_rstat|__cgroup_account|"
     r"pick_eevdf|avg_vruntime|update_min_vruntime|newidle_balance|sched_balance|"
     r"load_balance|idle_cpu|available_idle_cpu|select_idle|wakeup_preempt|"
     r"prepare_task_switch|context_switch|do_task_dead|task_tick|hrtick|__resched|"
     r"native_load_gs_index|load_new_mm_cr3|switch_ldt|ret_from_fork|"
     r"preempt_schedule|__cond_resched|smpboot_thread_fn|kthread|run_ksoftirqd)"),
    ("locks, irq-restore points", r"^(mutex_|__mutex|_raw_spin|__raw_spin|rtnl_|lock_sock|"
     r"release_sock|__lock_sock|__release_sock|_raw_read|_raw_write|down_|up_read|up_write|"
     r"queued_spin|native_queued|__pv_queued)"),
    ("irq, timer, tick", r"^(sysvec_|asm_sysvec|hrtimer_|__hrtimer|tick_|timekeeping|"
     r"update_process_times|run_timer|__run_timer|scheduler_tick|irqentry|common_interrupt|"
     r"asm_common|lapic_|native_apic|x2apic|clockevents|ktime_get|read_tsc|"
     r"__sysvec|irq_enter|timerqueue|enqueue_hrtimer|__remove_hrtimer|rcu_irq)"),
]
RULES = [(c, re.compile(r)) for c, r in RULES]
GENERIC = "other kernel"

# Our modules' functions by group: (group, regexp on the demangled name).
OURS = [
    ("send (rcan_raw sendmsg, rcan_send, can_send checks)", r"sendmsg|rcan_send|::send\b|alloc_tx|"
     r"set_sock_params|put_from_msg|queue_xmit|set_can_tx|by_index|DevRef"),
    ("canloop (start_xmit, FIFO, NAPI poll)", r"start_xmit|poll|drain|Ring|push|pop|"
     r"napi|can_xmit_start|set_can_rx|stats_|canloop|LoopDriver"),
    ("receive: dispatch (can_rcv, table lookup)", r"can_rcv|canfd_rcv|for_each_match|rcv\b|"
     r"valid_frame|deliver|RxTable|rxtable|lookup|Groups|KeyEntry|seen|mark"),
    ("receive: CAN_RAW rx callback", r"rx_trampoline|::rx\b|set_rx_meta|queue_rcv|into_owned|RxSkb"),
    ("recvmsg (rcan_raw)", r"recvmsg|recv_datagram|free_datagram|copy_from_skb|recv_cmsgs|set_name"),
]
OURS = [(g, re.compile(r)) for g, r in OURS]


def demangle(sym):
    """A readable tail of a Rust v0 symbol (its last identifiers)."""
    if not sym.startswith("_R"):
        return sym
    parts = []
    for m in re.finditer(r"(\d+)([A-Za-z_][A-Za-z0-9_]*)", sym):
        parts.append(m.group(2)[:int(m.group(1))])
    keep = [p for p in parts if p not in ("glue", "can", "kernel", "core") and not p.endswith("_mod")]
    return "::".join(keep[-4:]) or sym


def category(sym, dso, stack):
    mod = dso.strip("[]") if dso.startswith("[") and dso != "[kernel.kallsyms]" else None
    if mod in OUR_MODS or mod in ML_MODS:
        if stack == "mainline" or mod in ML_MODS:
            return f"mainline module ({mod})"
        d = demangle(sym)
        if not sym.startswith("_R"):
            return f"ours: C helpers, C-ABI entries ({mod})"
        for g, r in OURS:
            if r.search(d):
                return f"ours: {g}"
        return f"ours: other ({mod})"
    if dso not in ("[kernel.kallsyms]", "[unknown]") and not mod:
        return "user space (Python loop, libc)"
    if sym.startswith("[unknown]") or not sym:
        return "user space (Python loop, libc)" if not dso.startswith("[k") else GENERIC
    for c, r in RULES:
        if r.search(sym):
            return c
    return GENERIC


LINE = re.compile(r"^\s*(\S.*?)\s+(\d+)\s+\[(\d+)\]\s+(\d+)\.(\d+):\s+([0-9a-f]+)\s+(.*?)\s+\((.*)\)\s*$")


def marks(f):
    res = []
    for line in open(f):
        p = line.split()
        if p and p[0] == "PHASE":
            res.append((p[1], int(p[2]), int(p[3]), int(p[4])))
    return res


def tags(prefix, suffix):
    t = [os.path.basename(f)[len(prefix):-len(suffix)] for f in glob.glob(f"{out}/{prefix}*{suffix}")]
    return sorted(t, key=lambda x: int(x.split("-")[0]))


def lengths():
    print("== per frame, instructions (median over rounds), runs without perf ==")
    print(f"{'run':24s}{'frame':>10s}{'null':>10s}{'frame-null':>12s}{'rounds (frame-null)':>40s}")
    for tag in tags("marks-noperf-", ".txt"):
        per = collections.defaultdict(list)
        for name, _r, a, b in marks(f"{out}/marks-noperf-{tag}.txt"):
            per[name].append((b - a) / n)
        med = {k: sorted(v)[len(v) // 2] for k, v in per.items()}
        own = [f - z for f, z in zip(per["frame"], per["null"])]
        print(f"{tag:24s}{med['frame']:10.0f}{med['null']:10.0f}{med['frame'] - med['null']:12.0f}"
              f"{' '.join(f'{x:.0f}' for x in own):>40s}")
    print()


def main():
    lengths()
    res = {}
    for tag in tags("script-", ".txt.gz"):
        stack = tag.split("-", 1)[1]
        ph_marks = marks(f"{out}/marks-{tag}.txt")
        phases = [(name, a, b) for name, _r, a, b in ph_marks]
        rounds = collections.Counter(name for name, *_ in ph_marks)
        cnt = collections.defaultdict(collections.Counter)
        fn = collections.defaultdict(collections.Counter)
        percpu = collections.defaultdict(collections.Counter)
        comm1 = collections.defaultdict(collections.Counter)
        for line in gzip.open(f"{out}/script-{tag}.txt.gz", "rt", errors="replace"):
            m = LINE.match(line)
            if not m:
                continue
            comm, _tid, cpu, s, ns, _ip, sym, dso = m.groups()
            t = int(s) * 10**9 + int(ns.ljust(9, "0")[:9])
            ph = next((name for name, a, b in phases if a <= t < b), None)
            if ph is None:
                continue
            sym = re.sub(r"\+0x[0-9a-f]+$", "", sym)
            if sym in IDLE:
                percpu[ph][(int(cpu), "idle")] += 1
                continue
            if comm == "perf":
                # The profiler writing its samples (on whichever CPU is
                # free): not the workload's cost, left out.
                percpu[ph][(int(cpu), "perf tool")] += 1
                continue
            percpu[ph][(int(cpu), "busy")] += 1
            c = category(sym, dso, stack)
            cnt[ph][c] += 1
            name = demangle(sym) if not c.startswith("user space") else "(user space)"
            fn[ph][(c, name, int(cpu))] += 1
            if int(cpu) != 0:
                comm1[ph][(comm, c, name)] += 1
        res[tag] = (stack, cnt, fn, rounds, percpu, comm1)
    for ph in ("frame", "null", "idle"):
        print(f"== {ph}: instructions per frame (samples x {period} / frames), both CPUs ==")
        cats = sorted({c for t in res for c in res[t][1][ph]})
        print(f"{'category':58s}" + "".join(f"{t:>14s}" for t in res))
        for c in cats:
            print(f"{c:58s}" + "".join(
                f"{res[t][1][ph][c] * period / (res[t][3][ph] * n):14.0f}" for t in res))
        print(f"{'total (perf samples, busy)':58s}" + "".join(
            f"{sum(res[t][1][ph].values()) * period / (res[t][3][ph] * n):14.0f}" for t in res))
        for cpu in (0, 1):
            for kind in ("busy", "perf tool", "idle"):
                print(f"{f'  CPU {cpu} {kind}':58s}" + "".join(
                    f"{res[t][4][ph][(cpu, kind)] * period / (res[t][3][ph] * n):14.0f}" for t in res))
        for t in res:
            print(f"  top leaves, {t} (instructions per frame, CPU):")
            for (c, f, cpu), k in res[t][2][ph].most_common(top):
                print(f"    {k * period / (res[t][3][ph] * n):8.1f}  cpu{cpu}  {f}  [{c}]")
            if res[t][5][ph]:
                print(f"  CPU 1 (and above), {t}: by task and leaf")
                for (comm, c, f), k in res[t][5][ph].most_common(12):
                    print(f"    {k * period / (res[t][3][ph] * n):8.1f}  {comm}  {f}  [{c}]")
        print()


main()

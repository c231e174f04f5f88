#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-2.0
"""Workload for prof-bindclose.sh: N CAN_RAW sockets with one exact 11-bit
filter each (as rcan-bench's ``exact`` kind), bound to one device, then
closed; ROUNDS times. bind(2) and close(2) are called through libc directly
(no SIOCGIFINDEX per bind as Python's own bind would do), so the phases hold
nothing but those system calls and the Python loop around them. Prints
"PHASE name round start_ns end_ns" on CLOCK_MONOTONIC, the clock perf
records with -k CLOCK_MONOTONIC, so samples can be split by phase.

usage: bindclose.py IFACE N ROUNDS
"""
import ctypes
import os
import random
import resource
import socket
import struct
import sys
import time

CAN_SFF_MASK, CAN_EFF_FLAG, CAN_RTR_FLAG = 0x7FF, 0x80000000, 0x40000000
SOL_CAN_RAW, CAN_RAW_FILTER = 101, 1

iface, n, rounds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
resource.setrlimit(resource.RLIMIT_NOFILE, (n + 64, n + 64))
libc = ctypes.CDLL("libc.so.6", use_errno=True)
ifindex = socket.if_nametoindex(iface)
# struct sockaddr_can: family, pad, ifindex, then 16 bytes of address union
addr = ctypes.create_string_buffer(struct.pack("=HHi16x", socket.AF_CAN, 0, ifindex), 24)
big = ctypes.create_string_buffer(200)
mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG
mono = time.CLOCK_MONOTONIC
bind, close = libc.bind, libc.close
if os.environ.get("JITTER") == "1":
    # The profiled run: before each call a random short Python loop (0-15
    # steps, the same sequence for every stack and phase). Under icount
    # the workload is so regular that a fixed sampling period aliases with
    # its iterations and samples only a few points of them.
    rng = random.Random(1)
    steps = [rng.randrange(16) for _ in range(n)]

    def calls(fds):
        for fd, j in zip(fds, steps):
            for _ in range(j):
                pass
            yield fd
else:
    def calls(fds):
        return fds

for r in range(rounds):
    fds = []
    t0 = time.clock_gettime_ns(mono)
    for i in range(n):
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
        s.setsockopt(SOL_CAN_RAW, CAN_RAW_FILTER, struct.pack("=II", 1 + i % 0x7FE, mask))
        fds.append(s.detach())
    t1 = time.clock_gettime_ns(mono)
    for fd in calls(fds):
        if bind(fd, addr, 24) != 0:
            sys.exit(f"bind: errno {ctypes.get_errno()}")
    t2 = time.clock_gettime_ns(mono)
    # The floor of both loops: the same calls failing before the protocol
    # (an address longer than sockaddr_storage: EINVAL in the generic
    # code; fd -1: EBADF), so "bind - nullbind" is a bind's own cost.
    for fd in calls(fds):
        bind(fd, big, 200)
    t2n = time.clock_gettime_ns(mono)
    for fd in calls(fds):
        close(-1)
    t2c = time.clock_gettime_ns(mono)
    time.sleep(0.2)  # let the RCU work of the binds (none expected) settle
    t3 = time.clock_gettime_ns(mono)
    for fd in calls(fds):
        close(fd)
    t4 = time.clock_gettime_ns(mono)
    print(f"PHASE open {r} {t0} {t1}")
    print(f"PHASE bind {r} {t1} {t2}")
    print(f"PHASE nullbind {r} {t2} {t2n}")
    print(f"PHASE nullclose {r} {t2n} {t2c}")
    print(f"PHASE close {r} {t3} {t4}")
    time.sleep(0.5)  # RCU callbacks of the closes run here: not in "close"
    t5 = time.clock_gettime_ns(mono)
    print(f"PHASE after-close {r} {t4} {t5}")
    sys.stdout.flush()

#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-2.0
"""Workload for prof-frame.sh: CAN_RAW frames through an echoing device,
one thread, as rcan-bench's workload (b) with one receiver: a sender
socket (no filter, CAN_RAW_LOOPBACK on) and a receiver socket (one exact
11-bit filter, the frames' id), both bound to IFACE; BATCH frames are
sent, then BATCH received, N frames per round, ROUNDS rounds. send(2)
and recv(2) are called through libc directly, so each phase holds nothing
but those system calls and the Python loop around them. Every frame is
checked (id, sequence number): a lost or foreign frame ends the run.

Phases, each timed as a whole on CLOCK_MONOTONIC (the clock perf records
with -k CLOCK_MONOTONIC, so samples can be split by phase):

* ``frame``: the N frames sent and received;
* ``null``: the same loop with both calls failing in the generic code
  before any protocol (fd -1: EBADF), so ``frame - null`` is a frame's
  own cost beyond the system call and the loop;
* ``idle``: 0.3 s asleep, so work deferred past the frames (RCU
  callbacks, freeing) shows up apart.

Prints "PHASE name round start_ns end_ns" per phase.

usage: frame.py IFACE N ROUNDS [BATCH]
"""
import ctypes
import os
import random
import socket
import struct
import sys
import time

CAN_SFF_MASK, CAN_EFF_FLAG, CAN_RTR_FLAG = 0x7FF, 0x80000000, 0x40000000
SOL_CAN_RAW, CAN_RAW_FILTER, CAN_RAW_LOOPBACK = 101, 1, 3
FRAME_ID = 0x123

iface, n, rounds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
batch = int(sys.argv[4]) if len(sys.argv) > 4 else 64
if n % batch:
    sys.exit("N must be a multiple of BATCH")
libc = ctypes.CDLL("libc.so.6", use_errno=True)

tx = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
tx.setsockopt(SOL_CAN_RAW, CAN_RAW_FILTER, b"")
tx.setsockopt(SOL_CAN_RAW, CAN_RAW_LOOPBACK, 1)
tx.bind((iface,))
rx = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
rx.setsockopt(SOL_CAN_RAW, CAN_RAW_FILTER,
              struct.pack("=II", FRAME_ID, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG))
rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
# A frame that does not come within a second is lost (recv fails).
rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("=qq", 1, 0))
rx.bind((iface,))
txfd, rxfd = tx.fileno(), rx.fileno()

# One prepared frame image per sequence number of a batch (id, dlc 8,
# the sequence number in the first data word), so the loop builds nothing.
frames = [ctypes.create_string_buffer(struct.pack("=IB3xII", FRAME_ID, 8, i, 0), 16)
          for i in range(batch)]
rbuf = ctypes.create_string_buffer(16)
send, recv = libc.send, libc.recv
mono = time.clock_gettime_ns

if os.environ.get("JITTER") == "1":
    # The profiled run: before each call a random short Python loop (0-15
    # steps, the same sequence for every stack and phase), so that a fixed
    # sampling period does not alias with the icount-regular loop.
    rng = random.Random(1)
    steps = [(rng.randrange(16), rng.randrange(16)) for _ in range(batch)]
else:
    steps = [(0, 0)] * batch


def run(sfd, rfd, check):
    for _ in range(n // batch):
        for f, (j, _k) in zip(frames, steps):
            for _ in range(j):
                pass
            if send(sfd, f, 16, 0) != 16 and check:
                sys.exit(f"send: errno {ctypes.get_errno()}")
        for i, (_j, k) in enumerate(steps):
            for _ in range(k):
                pass
            if recv(rfd, rbuf, 16, 0) != 16 and check:
                sys.exit(f"recv: errno {ctypes.get_errno()} (frame lost?)")
            # Compared in both phases, so the null floor holds it too.
            if rbuf.raw[8:12] != frames[i].raw[8:12] and check:
                sys.exit(f"frame {i} of a batch came out of order or foreign")


for r in range(rounds):
    t0 = mono(time.CLOCK_MONOTONIC)
    run(txfd, rxfd, True)
    t1 = mono(time.CLOCK_MONOTONIC)
    run(-1, -1, False)
    t2 = mono(time.CLOCK_MONOTONIC)
    time.sleep(0.3)
    t3 = mono(time.CLOCK_MONOTONIC)
    print(f"PHASE frame {r} {t0} {t1}")
    print(f"PHASE null {r} {t1} {t2}")
    print(f"PHASE idle {r} {t2} {t3}")
    sys.stdout.flush()

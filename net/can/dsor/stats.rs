// SPDX-License-Identifier: GPL-2.0

//! The counters of `rcan_dsor`: part of the engine (`Engine::stats`,
//! under ENGINE), printed to `dmesg` at unload, where the tests read them.

#![forbid(unsafe_code)]

use kernel::prelude::*;

/// Counters, printed at unload (the tests read them from dmesg). Every
/// incoming message that is not delivered is counted once, by cause.
#[derive(Default)]
pub(crate) struct Stats {
    pub(crate) tx_ok: u64,
    pub(crate) tx_failed: u64,
    /// Messages queued on at least one socket, or handed to canip0.
    pub(crate) rx_delivered: u64,
    /// Headers refused: no socket (or canip0) wants the message (REFUSED).
    pub(crate) rx_refused_unwanted: u64,
    /// Headers refused: over `max_len` (TOO_LONG).
    pub(crate) rx_refused_too_long: u64,
    /// Headers refused: over `max_per_peer` or `max_bytes`, no slot, or no
    /// memory for the buffer (NO_MEMORY).
    pub(crate) rx_refused_no_memory: u64,
    /// Complete messages refused with the last frame: the receive queue of
    /// every socket that wanted it was full (NO_MEMORY).
    pub(crate) rx_queue_full: u64,
    /// Complete messages refused with the last frame: no socket (or no
    /// canip0 up) wants it any more (REFUSED).
    pub(crate) rx_unwanted_at_end: u64,
    /// Partial messages stopped because the last socket that wanted them
    /// was closed (their next body is refused, REFUSED).
    pub(crate) rx_closed: u64,
    /// Partial messages freed after `reasm_timeout_ms` without a frame.
    pub(crate) rx_timed_out: u64,
    /// Partial messages freed when `ifname` went down or the module was
    /// unloaded.
    pub(crate) rx_flushed: u64,
    /// Extra copies (a message wanted by several sockets) that did not fit
    /// a socket's receive queue; the message reached another socket.
    pub(crate) rx_copies_dropped: u64,
    /// Frames not sent because the send ring was full (recovered by
    /// retransmission).
    pub(crate) out_overflow: u64,
    pub(crate) send_errors: u64,
}

impl Stats {
    /// Prints the counters (two `dmesg` lines). Process context (unload).
    pub(crate) fn log_at_unload(&self) {
        pr_info!(
        "stopped: {} messages sent, {} failed, {} received, {} dropped, {} frames lost to a full send queue, {} send errors\n",
        self.tx_ok,
        self.tx_failed,
        self.rx_delivered,
        self.rx_refused_unwanted
            + self.rx_refused_too_long
            + self.rx_refused_no_memory
            + self.rx_queue_full
            + self.rx_unwanted_at_end
            + self.rx_closed
            + self.rx_timed_out
            + self.rx_flushed,
        self.out_overflow,
        self.send_errors
    );
        pr_info!(
        "not delivered: header refused {} no receiver, {} too long, {} no memory; last frame refused {} receive queue full, {} no receiver; {} receiver closed mid-message; {} timed out; {} flushed at ifdown/unload; {} extra copies dropped (queue full)\n",
        self.rx_refused_unwanted,
        self.rx_refused_too_long,
        self.rx_refused_no_memory,
        self.rx_queue_full,
        self.rx_unwanted_at_end,
        self.rx_closed,
        self.rx_timed_out,
        self.rx_flushed,
        self.rx_copies_dropped
    );
    }
}

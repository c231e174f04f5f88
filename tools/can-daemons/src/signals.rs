// SPDX-License-Identifier: GPL-2.0
//! How every daemon stops: SIGTERM and SIGINT are blocked in the main
//! thread before it starts any other (threads inherit the mask, so no
//! thread is interrupted) and read from a non-blocking signalfd that the
//! event loop polls beside its sockets, so a stop is handled between two
//! frames, never inside a write.

use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};

/// Blocks SIGTERM and SIGINT in the calling thread and returns a
/// non-blocking, close-on-exec signalfd that reads them. Call it first,
/// before any thread starts.
pub fn stop_signals() -> Result<SignalFd, String> {
    let mut mask = SigSet::empty();
    mask.add(Signal::SIGTERM);
    mask.add(Signal::SIGINT);
    mask.thread_block()
        .map_err(|e| format!("sigprocmask: {e}"))?;
    SignalFd::with_flags(&mask, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)
        .map_err(|e| format!("signalfd: {e}"))
}

/// The number of the signal waiting on `sfd`, 0 if none can be read.
pub fn signo(sfd: &SignalFd) -> u32 {
    sfd.read_signal()
        .ok()
        .flatten()
        .map(|s| s.ssi_signo)
        .unwrap_or(0)
}

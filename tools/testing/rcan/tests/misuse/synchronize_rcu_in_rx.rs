// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Unforgeable context proofs: process context"):
//! `synchronize_rcu` waits for a grace period and sleeps; its contract,
//! "process context, outside any RCU read-side critical section", was a
//! precondition on a safe function. Called from a protocol's receive
//! callback (softirq, inside pf_can's RCU read-side section) it sleeps
//! in atomic context and waits for a grace period its own caller holds
//! off: the CPU hangs. Only pf_can's entry points need it, in process
//! context, so it is now a private function of `glue/can/family.rs`.
// expect: E0425 cannot find function `synchronize_rcu` in module `crate::glue::sync`
#![forbid(unsafe_code)]

/// What a protocol's `rx` could do to wait for its old readers.
pub(crate) fn rx_waits_for_readers() {
    crate::glue::sync::synchronize_rcu();
}

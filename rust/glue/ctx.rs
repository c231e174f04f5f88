// SPDX-License-Identifier: GPL-2.0

//! Proofs of execution context, for the glue functions whose use is only
//! sound in one context. The glue lends a proof where the context really
//! holds; nothing above the glue can make one.
//!
//! Most contexts are carried by the types a callback receives instead: a
//! protocol's `proto_ops` methods get a [`Sock`](super::sock::Sock)
//! (process context: it can take the socket lock), its receive callback
//! and its timers get a [`SockView`](super::sock::SockView) (any context:
//! no lock). [`Process`] is for process-context code that reaches a sock
//! through a counted reference (a `/proc` read).

use core::marker::PhantomData;

/// Proof that the code holding it runs in process context and may sleep.
/// Lent by reference only, for one call: [`SeqFile::process`] (a `/proc`
/// file's `show`). Not constructible outside this file, not `Clone`, and
/// neither `Send` nor `Sync`, so a borrowed proof cannot be moved into a
/// timer, a job or another thread (which would need it `'static` and
/// `Send` anyway).
///
/// [`SeqFile::process`]: super::procfs::SeqFile::process
pub(crate) struct Process {
    _not_send: PhantomData<*mut ()>,
}

impl Process {
    /// A proof for the glue's own process-context callbacks to lend.
    /// Its users shorten the borrow to their call.
    pub(in crate::glue) const PROOF: &'static Process = &Process {
        _not_send: PhantomData,
    };
}

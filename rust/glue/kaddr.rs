// SPDX-License-Identifier: GPL-2.0

//! A kernel object's address as an opaque identity ([`KAddr`]): what
//! mainline's `/proc` files print with `%pK` (hashed, or zeros when
//! `kptr_restrict` hides it), e.g. `/proc/net/can-bcm`'s `socket`, `sk`
//! and `bo` fields. Only the glue makes one, from an object it knows to
//! be live ([`SockView::kaddr`], [`SockView::socket_kaddr`]); above the glue it
//! can be compared and printed ([`SeqFile::write_kaddr`]), never turned
//! back into a pointer or an integer, so protocol code has no
//! pointer-to-integer casts for it.

use super::procfs::SeqFile;
use super::sock::{Proto, SockView};

/// The address of a kernel object, for `%pK` and identity comparisons.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) struct KAddr(usize);

impl<T: Proto> SockView<T> {
    /// The address of this `struct sock` (mainline's `sk` and `bo` in
    /// `/proc/net/can-bcm`). Any context.
    pub(crate) fn kaddr(&self) -> KAddr {
        KAddr(self.as_ptr() as usize)
    }

    /// The address of the sock's `struct socket` (`sk->sk_socket`; 0
    /// once orphaned). Any context.
    pub(crate) fn socket_kaddr(&self) -> KAddr {
        KAddr(self.socket_addr())
    }
}

impl SeqFile<'_> {
    /// Writes `a` as `%pK` does: printed, never dereferenced. Process
    /// context (a `show`).
    pub(crate) fn write_kaddr(&mut self, a: KAddr) {
        self.write_kptr(a.0);
    }
}

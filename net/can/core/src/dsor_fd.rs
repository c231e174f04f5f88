// SPDX-License-Identifier: GPL-2.0
//! DSOR message transfer with CAN FD bodies, the optional extension of
//! `Documentation/networking/rcan/dsor-wire.rst`, "Message transfer with
//! CAN FD bodies (extension)": the FD header (12 bytes, offering a body
//! size), the 4-byte ack that chooses the body size, segmentation of a
//! message into bodies of size B with the CAN FD length and padding rules,
//! the check and copy of a received body, and the sender's per-node
//! "FD or classic" memory.
//!
//! The wire items live in `dsor_wire` (with an `fd_` prefix where a
//! classic name exists), since the receiver `dsor_rx` uses them; they are
//! re-exported here under the names below. With body size 8
//! ([`BodySize::CLASSIC`]) they give exactly the classic frames of
//! `dsor_wire`/`dsor_tx` (classic frames, FDF 0).
//!
//! Pure, `no_std`, allocation-free: called in any context (process or
//! softirq) with the caller's locking; nothing here is shared.

use super::dsor_tx::{Transfer, TxStep};
use super::dsor_wire::MAX_NODE;

// Re-exports for users of this module's API (rcan-core's tests and
// tools); the kernel's rcan_core.rs compiles the file too and uses few.
#[allow(unused_imports)]
pub use super::dsor_wire::{
    fd_body_count as body_count, fd_body_frame as body_frame, fd_body_frame_len as body_frame_len,
    fd_body_len_ok as body_len_ok, fd_body_payload as body_payload, fd_dlc_to_len, fd_len_round_up,
    fd_len_to_dlc, fd_store_body as store_body, is_fd_len, BodySize, FdAck, FdFrame, FdHeader,
    FD_ACK_LEN, FD_HEADER_LEN, FD_LENS, FD_MAX_LEN,
};

/// What the sender knows of a node (rcan-core's sender policy, not on the
/// wire).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum PeerMode {
    /// Nothing yet: try an FD header, fall back at the first T_ack.
    Unknown,
    /// It acked an FD header: keep sending FD headers.
    Fd,
    /// An FD header to it went unanswered: classic headers only.
    Classic,
}

/// The sender's per-destination "FD or classic" memory, 128 nodes, 32
/// bytes. The caller's lock protects it (the module's sender lock).
#[derive(Clone, Debug, Default)]
pub struct FdPeers {
    fd: u128,
    classic: u128,
}

impl FdPeers {
    /// Every node unknown.
    pub const fn new() -> Self {
        FdPeers { fd: 0, classic: 0 }
    }

    /// What is known of node `dst` (`Classic` for `dst` > 0x7f).
    pub const fn mode(&self, dst: u8) -> PeerMode {
        if dst > MAX_NODE || self.classic & (1 << dst) != 0 {
            PeerMode::Classic
        } else if self.fd & (1 << dst) != 0 {
            PeerMode::Fd
        } else {
            PeerMode::Unknown
        }
    }

    /// Whether to send an FD header for an `len`-byte message to `dst` (on
    /// an FD interface): L > 8 and `dst` not known to be classic.
    pub const fn use_fd_header(&self, dst: u8, len: u16) -> bool {
        len > 8 && !matches!(self.mode(dst), PeerMode::Classic)
    }

    /// `dst` acked an FD header (DLC 4, any body size).
    pub fn on_fd_ack(&mut self, dst: u8) {
        if dst <= MAX_NODE {
            self.fd |= 1 << dst;
            self.classic &= !(1 << dst);
        }
    }

    /// The sender fell back to the classic header toward `dst`.
    pub fn on_fallback(&mut self, dst: u8) {
        if dst <= MAX_NODE {
            self.classic |= 1 << dst;
            self.fd &= !(1 << dst);
        }
    }

    /// Forget everything (for example when the interface goes down).
    pub fn forget_all(&mut self) {
        *self = FdPeers::new();
    }
}

/// The sender with CAN FD bodies: the one DSOR sender, `dsor_tx::Transfer`,
/// sending [`FdFrame`]s; make it with `Transfer::new_fd` (or
/// `FdTransfer::new_fd`). Without an offer it behaves, frame for frame, as
/// the classic `Transfer`.
pub type FdTransfer = Transfer<FdFrame>;

/// What the caller of [`FdTransfer`] must do after an event.
pub type FdStep = TxStep<FdFrame>;

#[cfg(test)]
mod tests {
    use super::super::dsor_wire;
    use super::*;

    #[test]
    fn lengths() {
        assert_eq!(fd_len_round_up(0), Some(0));
        assert_eq!(fd_len_round_up(8), Some(8));
        assert_eq!(fd_len_round_up(9), Some(12));
        assert_eq!(fd_len_round_up(26), Some(32));
        assert_eq!(fd_len_round_up(49), Some(64));
        assert_eq!(fd_len_round_up(65), None);
        for dlc in 0..16u8 {
            assert_eq!(fd_len_to_dlc(fd_dlc_to_len(dlc) as usize), Some(dlc));
        }
        assert_eq!(fd_len_to_dlc(13), None);
        assert_eq!(BodySize::new(9), None);
        assert_eq!(BodySize::new(8), Some(BodySize::CLASSIC));
        assert_eq!(body_count(65535, BodySize::MAX), 1024);
        assert_eq!(body_count(65535, BodySize::new(12).unwrap()), 5462);
        for len in 0..200u16 {
            for k in 0..30 {
                assert_eq!(
                    body_frame_len(len, BodySize::CLASSIC, k),
                    dsor_wire::body_dlc(len, k)
                );
            }
            assert_eq!(
                body_count(len, BodySize::CLASSIC),
                dsor_wire::body_count(len)
            );
        }
    }

    #[test]
    fn peers() {
        let mut p = FdPeers::new();
        assert!(p.use_fd_header(3, 9));
        assert!(!p.use_fd_header(3, 8));
        p.on_fallback(3);
        assert_eq!(p.mode(3), PeerMode::Classic);
        assert!(!p.use_fd_header(3, 100));
        p.on_fd_ack(3);
        p.on_fd_ack(0x7f);
        assert_eq!(p.mode(3), PeerMode::Fd);
        assert_eq!(p.mode(0x7f), PeerMode::Fd);
        assert_eq!(p.mode(0x80), PeerMode::Classic);
        p.forget_all();
        assert_eq!(p.mode(3), PeerMode::Unknown);
    }
}

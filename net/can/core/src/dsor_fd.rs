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

use super::dsor_tx::TxError;
use super::dsor_wire::{
    Ack, AckStatus, DsorId, Frame, FrameType, Header, Timers, CHANNELS, MAX_NODE,
};

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

/// What the caller of [`FdTransfer`] must do after an event.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum FdStep {
    /// Nothing (event not for this transfer, or not yet due).
    Nothing,
    /// Send this frame (an FD frame if `fdf`); the deadline was re-armed.
    Send(FdFrame),
    /// The ack of the last frame arrived: the message was delivered.
    Done,
    /// The message failed (see `TxStep::Failed`).
    Failed(TxError),
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum FdState {
    New,
    Waiting,
    Done,
    Failed,
}

/// The sender of one message on one stream, with the FD header, the
/// fallback to the classic header and bodies of the body size the
/// receiver chose (dsor-wire.rst, "Message transfer with CAN FD bodies",
/// "Sender"). Without an offer it behaves, frame for frame, as
/// `dsor_tx::Transfer`. Like `Transfer` it holds no message buffer; the
/// caller's lock protects it.
#[derive(Clone, Debug)]
pub struct FdTransfer {
    src: u8,
    dst: u8,
    chan: u8,
    prio: u8,
    header: Header,
    first_q: bool,
    /// B_max while the FD header is the header in flight; `None` for a
    /// classic header (no offer, or after the fallback).
    offer: Option<BodySize>,
    fell_back: bool,
    /// The body size in use: the receiver's choice once the FD header was
    /// acked, else 8.
    body: BodySize,
    index: u16,
    retx: u32,
    deadline: Option<u64>,
    state: FdState,
    ack_timeout_ms: u32,
    max_retx: u32,
}

impl FdTransfer {
    /// A transfer like `Transfer::new`, offering body sizes up to `offer`
    /// with an FD header if `offer` is an FD size and the message is longer
    /// than 8 bytes ([`FdPeers::use_fd_header`] decides whether to offer);
    /// otherwise a classic transfer.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        src: u8,
        dst: u8,
        chan: u8,
        prio: u8,
        header: Header,
        first_q: bool,
        timers: &Timers,
        offer: Option<BodySize>,
    ) -> Self {
        let offer = match offer {
            Some(b) if FdHeader::new(header, b).is_some() => Some(b),
            _ => None,
        };
        FdTransfer {
            src: src & MAX_NODE,
            dst: dst & MAX_NODE,
            chan: chan & (CHANNELS - 1),
            prio,
            header,
            first_q,
            offer,
            fell_back: false,
            body: BodySize::CLASSIC,
            index: 0,
            retx: 0,
            deadline: None,
            state: FdState::New,
            ack_timeout_ms: timers.ack_timeout_ms,
            max_retx: timers.max_retx,
        }
    }

    fn q_of(&self, index: u16) -> bool {
        self.first_q ^ (index & 1 == 1)
    }

    fn id(&self, ftype: FrameType, index: u16) -> DsorId {
        DsorId {
            prio: self.prio,
            dst: self.dst,
            src: self.src,
            ftype,
            seq: self.q_of(index),
            chan: self.chan,
        }
    }

    fn last_index(&self) -> u16 {
        body_count(self.header.len, self.body)
    }

    /// Frame `index`: the header in flight (FD or classic) for 0, body
    /// `index` with the current body size otherwise.
    pub fn frame(&self, msg: &[u8], index: u16) -> FdFrame {
        if index == 0 {
            let id = self.id(FrameType::Header, 0);
            return match self.offer {
                Some(b) => FdHeader {
                    header: self.header,
                    max_body: b,
                }
                .frame(&id),
                None => Frame::header(&id, &self.header).into(),
            };
        }
        body_frame(
            &self.id(FrameType::Body, index),
            msg,
            self.header.len,
            self.body,
            index,
        )
    }

    /// The header frame; arms the deadline. Calling it again restarts the
    /// transfer from the header (the one in flight) with a fresh budget.
    pub fn start(&mut self, msg: &[u8], now_ms: u64) -> FdFrame {
        self.index = 0;
        self.retx = 0;
        self.body = BodySize::CLASSIC;
        self.state = FdState::Waiting;
        self.deadline = Some(now_ms + self.ack_timeout_ms as u64);
        self.frame(msg, 0)
    }

    /// An ack frame from the node's receive path (see `Transfer::on_ack`).
    /// The ack of index 0 must be the 4-byte FD ack while the FD header is
    /// in flight and a classic ack (DLC 2 or 3) otherwise.
    pub fn on_ack(&mut self, id: &DsorId, data: &[u8], msg: &[u8], now_ms: u64) -> FdStep {
        if self.state != FdState::Waiting
            || id.ftype != FrameType::Ack
            || id.src != self.dst
            || id.dst != self.src
            || id.chan != self.chan
            || id.seq != self.q_of(self.index)
        {
            return FdStep::Nothing;
        }
        let status = match self.offer {
            Some(offer) if self.index == 0 => match FdAck::decode(data, offer) {
                Some(a) => {
                    if a.status == AckStatus::Ok {
                        self.body = a.body;
                    }
                    a.status
                }
                None => return FdStep::Nothing,
            },
            _ => match Ack::decode(data) {
                Some(a) if a.index == self.index => a.status,
                _ => return FdStep::Nothing,
            },
        };
        let err = match status {
            AckStatus::Ok => None,
            AckStatus::Refused => Some(TxError::Refused),
            AckStatus::NoMemory => Some(TxError::NoMemory),
            AckStatus::TooLong => Some(TxError::TooLong),
        };
        if let Some(e) = err {
            self.state = FdState::Failed;
            self.deadline = None;
            return FdStep::Failed(e);
        }
        if self.index == self.last_index() {
            self.state = FdState::Done;
            self.deadline = None;
            return FdStep::Done;
        }
        self.index += 1;
        self.retx = 0;
        self.deadline = Some(now_ms + self.ack_timeout_ms as u64);
        FdStep::Send(self.frame(msg, self.index))
    }

    /// The deadline passed (see `Transfer::on_timer`). The first
    /// retransmission of an unanswered FD header is the fallback: the
    /// classic header of the message, same Q.
    pub fn on_timer(&mut self, msg: &[u8], now_ms: u64) -> FdStep {
        match self.deadline {
            Some(d) if self.state == FdState::Waiting && now_ms >= d => {}
            _ => return FdStep::Nothing,
        }
        if self.retx >= self.max_retx {
            self.state = FdState::Failed;
            self.deadline = None;
            return FdStep::Failed(TxError::TimedOut);
        }
        self.retx += 1;
        if self.index == 0 && self.offer.is_some() {
            self.offer = None;
            self.fell_back = true;
        }
        self.deadline = Some(now_ms + self.ack_timeout_ms as u64);
        FdStep::Send(self.frame(msg, self.index))
    }

    /// When [`FdTransfer::on_timer`] must be called next.
    pub fn deadline(&self) -> Option<u64> {
        self.deadline
    }

    /// The Q for the next message's header on this stream.
    pub fn next_q(&self) -> bool {
        if self.state == FdState::New {
            self.first_q
        } else {
            !self.q_of(self.index)
        }
    }

    /// Whether the last frame was sent at least once (an unknown outcome
    /// on [`TxError::TimedOut`]).
    pub fn last_frame_sent(&self) -> bool {
        self.state != FdState::New
            && self.index == self.last_index()
            && (self.index > 0 || self.offer.is_none())
    }

    /// Whether the transfer ended.
    pub fn finished(&self) -> bool {
        matches!(self.state, FdState::Done | FdState::Failed)
    }

    /// Whether the sender fell back from the FD to the classic header
    /// (for [`FdPeers::on_fallback`]).
    pub fn fell_back(&self) -> bool {
        self.fell_back
    }

    /// Whether the receiver acked the FD header (for
    /// [`FdPeers::on_fd_ack`]).
    pub fn fd_acked(&self) -> bool {
        self.offer.is_some() && self.index > 0
    }

    /// The body size in use (8 until an FD header was acked).
    pub fn body_size(&self) -> BodySize {
        self.body
    }

    /// The message's header.
    pub fn header(&self) -> &Header {
        &self.header
    }
}

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

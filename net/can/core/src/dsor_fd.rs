// SPDX-License-Identifier: GPL-2.0
//! DSOR message transfer with CAN FD bodies, the optional extension of
//! `Documentation/networking/rcan/dsor-wire.rst`, "Message transfer with
//! CAN FD bodies (extension)": the FD header (12 bytes, offering a body
//! size), the 4-byte ack that chooses the body size, segmentation of a
//! message into bodies of size B with the CAN FD length and padding rules,
//! the check and copy of a received body, and the sender's per-node
//! "FD or classic" memory.
//!
//! With body size 8 ([`BodySize::CLASSIC`]) everything here gives exactly
//! the classic frames of `dsor_wire`/`dsor_tx` (classic frames, FDF 0).
//! The classic code paths do not use this module and are unchanged.
//!
//! Pure, `no_std`, allocation-free: called in any context (process or
//! softirq) with the caller's locking; nothing here is shared.

use super::dsor_tx::TxError;
use super::dsor_wire::{
    Ack, AckStatus, DsorId, Frame, FrameType, Header, MsgKind, Timers, CHANNELS, MAX_NODE,
};

/// Largest CAN FD payload.
pub const FD_MAX_LEN: usize = 64;
/// The CAN FD lengths above 8 (DLC 9-15), ISO 11898-1:2015.
pub const FD_LENS: [u8; 7] = [12, 16, 20, 24, 32, 48, 64];
/// Length of an FD header frame (DLC 9).
pub const FD_HEADER_LEN: u8 = 12;
/// DLC of the ack of an FD header.
pub const FD_ACK_LEN: u8 = 4;

/// The smallest valid CAN FD length >= `r` (0-8 are themselves); `None`
/// for `r` > 64.
pub const fn fd_len_round_up(r: usize) -> Option<u8> {
    if r <= 8 {
        return Some(r as u8);
    }
    let mut i = 0;
    while i < FD_LENS.len() {
        if FD_LENS[i] as usize >= r {
            return Some(FD_LENS[i]);
        }
        i += 1;
    }
    None
}

/// Whether `len` is a valid CAN FD frame length (0-8, 12, 16, 20, 24, 32,
/// 48, 64).
pub const fn is_fd_len(len: usize) -> bool {
    matches!(fd_len_round_up(len), Some(l) if l as usize == len)
}

/// The DLC (0-15) of a valid CAN FD length; `None` otherwise.
pub const fn fd_len_to_dlc(len: usize) -> Option<u8> {
    if len <= 8 {
        return Some(len as u8);
    }
    let mut i = 0;
    while i < FD_LENS.len() {
        if FD_LENS[i] as usize == len {
            return Some(9 + i as u8);
        }
        i += 1;
    }
    None
}

/// The length of a CAN FD DLC (0-15; higher bits ignored).
pub const fn fd_dlc_to_len(dlc: u8) -> u8 {
    let d = dlc & 0xf;
    if d <= 8 {
        d
    } else {
        FD_LENS[(d - 9) as usize]
    }
}

/// The body size B of a message: 8 (classic bodies) or a CAN FD length
/// 12-64.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Debug)]
pub struct BodySize(u8);

impl BodySize {
    /// 8: classic bodies.
    pub const CLASSIC: BodySize = BodySize(8);
    /// 64: the largest.
    pub const MAX: BodySize = BodySize(64);
    /// Every body size, smallest first.
    pub const ALL: [BodySize; 8] = [
        BodySize(8),
        BodySize(12),
        BodySize(16),
        BodySize(20),
        BodySize(24),
        BodySize(32),
        BodySize(48),
        BodySize(64),
    ];

    /// The body size `b`, if it is 8 or one of the FD lengths 12-64.
    pub const fn new(b: u8) -> Option<Self> {
        if b == 8 || (b > 8 && is_fd_len(b as usize)) {
            Some(BodySize(b))
        } else {
            None
        }
    }

    /// The size in bytes.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Whether bodies of this size are CAN FD frames (B > 8).
    pub const fn is_fd(self) -> bool {
        self.0 > 8
    }
}

/// Number of bodies of an `len`-byte message with body size `b`:
/// ceil(len / B).
pub const fn body_count(len: u16, b: BodySize) -> u16 {
    (len as u32).div_ceil(b.0 as u32) as u16
}

/// Payload bytes of body `k` (1-based): min(B, len - B(k-1)); 0 if there
/// is no such body.
pub const fn body_payload(len: u16, b: BodySize, k: u16) -> usize {
    if k == 0 || k > body_count(len, b) {
        return 0;
    }
    let rest = len as usize - b.0 as usize * (k as usize - 1);
    if rest > b.0 as usize {
        b.0 as usize
    } else {
        rest
    }
}

/// On-wire length of body `k`: its payload rounded up to a CAN FD length
/// (only the last body can need padding); 0 if there is no such body. For
/// [`BodySize::CLASSIC`] this is `dsor_wire::body_dlc`.
pub const fn body_frame_len(len: u16, b: BodySize, k: u16) -> u8 {
    match fd_len_round_up(body_payload(len, b, k)) {
        Some(l) => l,
        None => 0,
    }
}

/// A DSOR frame that may be a CAN FD frame.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct FdFrame {
    /// 29-bit identifier (no `CAN_EFF_FLAG`).
    pub id: u32,
    /// Length in bytes: 0-8 or a CAN FD length (12-64 only with `fdf`).
    pub len: u8,
    /// Whether this is a CAN FD frame (FDF 1).
    pub fdf: bool,
    /// Data; bytes from `len` on, and padding, are zero.
    pub data: [u8; FD_MAX_LEN],
}

impl FdFrame {
    /// The data bytes (`data[..len]`), padding included.
    pub fn payload(&self) -> &[u8] {
        &self.data[..(self.len as usize).min(FD_MAX_LEN)]
    }

    /// The classic frame, if this is one (not FD).
    pub fn classic(&self) -> Option<Frame> {
        if self.fdf || self.len > 8 {
            return None;
        }
        let mut data = [0; 8];
        data.copy_from_slice(&self.data[..8]);
        Some(Frame {
            id: self.id,
            len: self.len,
            data,
        })
    }
}

impl From<Frame> for FdFrame {
    fn from(f: Frame) -> Self {
        let mut data = [0; FD_MAX_LEN];
        data[..8].copy_from_slice(&f.data);
        FdFrame {
            id: f.id,
            len: f.len,
            fdf: false,
            data,
        }
    }
}

/// Contents of an FD header frame: the classic header plus the largest
/// body size the sender offers (12-64).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct FdHeader {
    /// Length and addressing, as in a classic header.
    pub header: Header,
    /// B_max: the largest body size offered; an FD size (12-64).
    pub max_body: BodySize,
}

impl FdHeader {
    /// Length of an FD header frame ([`FD_HEADER_LEN`]).
    pub const LEN: usize = FD_HEADER_LEN as usize;

    /// An FD header for `header` offering `max_body`; `None` if the
    /// message is too short for one (L <= 8) or `max_body` is not an FD
    /// size.
    pub const fn new(header: Header, max_body: BodySize) -> Option<Self> {
        if header.len <= 8 || !max_body.is_fd() {
            return None;
        }
        Some(FdHeader { header, max_body })
    }

    /// Write the 12 data bytes into `out` (the rest zeroed); returns
    /// [`FD_HEADER_LEN`].
    pub fn encode(&self, out: &mut [u8; FD_MAX_LEN]) -> u8 {
        *out = [0; FD_MAX_LEN];
        let mut classic = [0; 8];
        let dlc = self.header.encode(&mut classic);
        out[..8].copy_from_slice(&classic);
        out[8] = dlc;
        out[9] = self.max_body.get();
        FD_HEADER_LEN
    }

    /// Parse an FD header frame's data (its length is the frame's): `None`
    /// unless it is 12 bytes with a type byte of 4, 6 or 8, an FD size in
    /// byte 9 and L > 8. Bytes 10-11 and the bytes past the classic
    /// header's length are ignored.
    pub fn decode(data: &[u8]) -> Option<Self> {
        if data.len() != FD_HEADER_LEN as usize {
            return None;
        }
        let dlc = data[8] as usize;
        if !matches!(dlc, 4 | 6 | 8) {
            return None;
        }
        let header = Header::decode(&data[..dlc])?;
        let max_body = BodySize::new(data[9])?;
        FdHeader::new(header, max_body)
    }

    /// The FD header frame with identifier `id` (its type is set to
    /// header).
    pub fn frame(&self, id: &DsorId) -> FdFrame {
        let mut data = [0; FD_MAX_LEN];
        let len = self.encode(&mut data);
        FdFrame {
            id: DsorId {
                ftype: FrameType::Header,
                ..*id
            }
            .to_can_id(),
            len,
            fdf: true,
            data,
        }
    }

    /// The message type (as for the classic header).
    pub fn kind(&self) -> MsgKind {
        self.header.kind
    }
}

/// Contents of the ack of an FD header (index 0, DLC 4).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct FdAck {
    /// Status, as for classic acks.
    pub status: AckStatus,
    /// The body size the receiver chose (8 with a non-OK status).
    pub body: BodySize,
}

impl FdAck {
    /// Write the ack's data into `out` (unused bytes zeroed); returns
    /// [`FD_ACK_LEN`].
    pub fn encode(&self, out: &mut [u8; 8]) -> u8 {
        *out = [0; 8];
        out[2] = self.status.code();
        out[3] = self.body.get();
        FD_ACK_LEN
    }

    /// Parse an ack frame's data as the ack of an FD header that offered
    /// `offered`: `None` unless it is 4 bytes, index 0, a known status
    /// and (for status OK) a body size not above `offered`.
    pub fn decode(data: &[u8], offered: BodySize) -> Option<Self> {
        let [0, 0, s, b] = *data else {
            return None;
        };
        let status = AckStatus::from_code(s)?;
        let body = match status {
            AckStatus::Ok => match BodySize::new(b) {
                Some(b) if b <= offered => b,
                _ => return None,
            },
            _ => BodySize::CLASSIC,
        };
        Some(FdAck { status, body })
    }

    /// The ack frame with identifier `id` (a classic frame).
    pub fn frame(&self, id: &DsorId) -> Frame {
        let mut data = [0; 8];
        let len = self.encode(&mut data);
        Frame {
            id: id.to_can_id(),
            len,
            data,
        }
    }
}

/// Body `k` (1 ..= n) of the `len`-byte message `msg` with body size `b`,
/// identifier `id` (type set to body; the caller sets Q). The payload is
/// `msg[B(k-1) ..]` (missing bytes are sent as zero, as in
/// `Transfer::frame`), padded with zeros to [`body_frame_len`]. An FD
/// frame for B > 8, a classic one (identical to the classic body) for
/// B = 8. Length 0 if there is no body `k`.
pub fn body_frame(id: &DsorId, msg: &[u8], len: u16, b: BodySize, k: u16) -> FdFrame {
    let r = body_payload(len, b, k);
    let off = if k == 0 {
        0
    } else {
        b.get() as usize * (k as usize - 1)
    };
    let mut data = [0; FD_MAX_LEN];
    for (i, d) in data.iter_mut().enumerate().take(r) {
        *d = msg.get(off + i).copied().unwrap_or(0);
    }
    FdFrame {
        id: DsorId {
            ftype: FrameType::Body,
            ..*id
        }
        .to_can_id(),
        len: body_frame_len(len, b, k),
        fdf: b.is_fd(),
        data,
    }
}

/// Whether `frame_len` is the right length of body `k` of an `len`-byte
/// message with body size `b`.
pub const fn body_len_ok(len: u16, b: BodySize, k: u16, frame_len: usize) -> bool {
    let want = body_frame_len(len, b, k);
    want != 0 && frame_len == want as usize
}

/// Store received body `k` (its frame's data bytes, padding included) of
/// an `len`-byte message with body size `b` into `buf`, the message
/// buffer (at least `len` bytes). Returns the payload bytes stored, or
/// `None` (nothing stored) if the body's length is wrong (malformed) or
/// `buf` is too short. Padding values are ignored.
pub fn store_body(buf: &mut [u8], len: u16, b: BodySize, k: u16, data: &[u8]) -> Option<usize> {
    if !body_len_ok(len, b, k, data.len()) {
        return None;
    }
    let r = body_payload(len, b, k);
    let off = b.get() as usize * (k as usize - 1);
    buf.get_mut(off..off + r)?.copy_from_slice(&data[..r]);
    Some(r)
}

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

// SPDX-License-Identifier: GPL-2.0
//! DSOR sender: one message on one stream (source, destination, channel),
//! stop-and-wait with retransmission (thesis 5.3.3, Idle RQ;
//! `Documentation/networking/rcan/dsor-wire.rst`, "Sender"), and the
//! per-destination channel allocator that remembers each stream's
//! sequence bit.
//!
//! The same [`Transfer`] sends with CAN FD bodies (`dsor_fd`, the
//! extension of dsor-wire.rst) when it is made with an offer.
//!
//! [`Transfer`] holds no message buffer: the caller passes the message
//! bytes to every call that may have to build a frame, so the same state
//! machine runs over a kernel `skb`-like buffer or a host `Vec`.

use core::marker::PhantomData;

use super::dsor_wire::{
    fd_body_count, fd_body_frame, Ack, AckStatus, BodySize, DsorId, FdAck, FdFrame, FdHeader,
    Frame, FrameType, Header, Timers, CHANNELS, MAX_NODE,
};

/// Why a message failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum TxError {
    /// N_retx retransmissions of one frame went unanswered (`ETIMEDOUT`).
    TimedOut,
    /// The receiver answered REFUSED (`ECONNREFUSED`).
    Refused,
    /// The receiver answered NO_MEMORY (`ENOBUFS`).
    NoMemory,
    /// The receiver answered TOO_LONG (`EMSGSIZE`).
    TooLong,
}

impl TxError {
    /// The Linux errno (positive) this failure is reported with.
    pub const fn errno(self) -> i32 {
        match self {
            TxError::TimedOut => 110, // ETIMEDOUT
            TxError::Refused => 111,  // ECONNREFUSED
            TxError::NoMemory => 105, // ENOBUFS
            TxError::TooLong => 90,   // EMSGSIZE
        }
    }
}

/// A frame type a [`Transfer`] sends: [`Frame`] for a classic-only
/// transfer ([`Transfer::new`]), [`FdFrame`] for one that may offer CAN FD
/// bodies ([`Transfer::new_fd`], `dsor_fd`).
pub trait TxFrame: Copy {
    /// The frame to send for `f`, which the transfer built. A classic-only
    /// transfer never builds an FD frame (it has no offer, so its body
    /// size stays 8), so for [`Frame`] this takes the classic part.
    fn from_fd(f: FdFrame) -> Self;
}

impl TxFrame for FdFrame {
    fn from_fd(f: FdFrame) -> Self {
        f
    }
}

impl TxFrame for Frame {
    fn from_fd(f: FdFrame) -> Self {
        let mut data = [0; 8];
        data.copy_from_slice(&f.data[..8]);
        Frame {
            id: f.id,
            len: f.len.min(8),
            data,
        }
    }
}

/// What the caller must do after an event.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum TxStep<F = Frame> {
    /// Nothing (event not for this transfer, or not yet due).
    Nothing,
    /// Send this frame (the next frame, or a retransmission; an FD frame
    /// if `F` is [`FdFrame`] with `fdf`); the deadline was re-armed.
    Send(F),
    /// The ack of the last frame arrived: the message was delivered.
    Done,
    /// The message failed. With [`TxError::TimedOut`] and
    /// [`Transfer::last_frame_sent`] true the outcome is unknown (the
    /// receiver may have delivered it).
    Failed(TxError),
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum State {
    New,
    Waiting,
    Done,
    Failed,
}

/// One message in flight on the stream (src, dst, chan): the one sender
/// of DSOR, classic and with CAN FD bodies.
///
/// With no offer (always for `Transfer<Frame>`, from [`Transfer::new`])
/// it is the classic sender of dsor-wire.rst, "Sender": classic header,
/// classic bodies. With an offer ([`Transfer::new_fd`]) it sends the FD
/// header, falls back to the classic header at the first T_ack without
/// an answer, and sends bodies of the body size the receiver chose
/// (dsor-wire.rst, "Message transfer with CAN FD bodies", "Sender").
/// Holds no message buffer; the caller's lock protects it.
#[derive(Clone, Debug)]
pub struct Transfer<F: TxFrame = Frame> {
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
    /// Index of the frame sent last and waited for (0 = header).
    index: u16,
    /// Retransmissions of frame `index` so far.
    retx: u32,
    deadline: Option<u64>,
    state: State,
    ack_timeout_ms: u32,
    max_retx: u32,
    _frame: PhantomData<F>,
}

impl Transfer<Frame> {
    /// A classic transfer of the message described by `header` from node
    /// `src` to node `dst` on channel `chan` with priority `prio`;
    /// `first_q` is the header's Q (from [`TxStreams::alloc`]). Nothing is
    /// sent yet.
    pub fn new(
        src: u8,
        dst: u8,
        chan: u8,
        prio: u8,
        header: Header,
        first_q: bool,
        timers: &Timers,
    ) -> Self {
        Self::build(src, dst, chan, prio, header, first_q, timers, None)
    }
}

impl Transfer<FdFrame> {
    /// A transfer like [`Transfer::new`] that sends [`FdFrame`]s, offering
    /// body sizes up to `offer` with an FD header if `offer` is an FD size
    /// and the message is longer than 8 bytes (`FdPeers::use_fd_header`
    /// decides whether to offer); otherwise a classic transfer.
    #[allow(clippy::too_many_arguments)]
    pub fn new_fd(
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
        Self::build(src, dst, chan, prio, header, first_q, timers, offer)
    }
}

impl<F: TxFrame> Transfer<F> {
    #[allow(clippy::too_many_arguments)]
    fn build(
        src: u8,
        dst: u8,
        chan: u8,
        prio: u8,
        header: Header,
        first_q: bool,
        timers: &Timers,
        offer: Option<BodySize>,
    ) -> Self {
        Transfer {
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
            state: State::New,
            ack_timeout_ms: timers.ack_timeout_ms,
            max_retx: timers.max_retx,
            _frame: PhantomData,
        }
    }

    /// The message's header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Channel of this transfer.
    pub fn chan(&self) -> u8 {
        self.chan
    }

    /// Destination node of this transfer.
    pub fn dst(&self) -> u8 {
        self.dst
    }

    /// Q of frame `index` (header Q XOR index parity).
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

    /// Frame `index` of the message: the header in flight (FD or classic)
    /// for 0, body `index` with the current body size otherwise. `msg`
    /// should hold `header.len` bytes; missing bytes are sent as zero,
    /// extra bytes are not sent.
    pub fn frame(&self, msg: &[u8], index: u16) -> F {
        if index == 0 {
            let id = self.id(FrameType::Header, 0);
            return F::from_fd(match self.offer {
                Some(b) => FdHeader {
                    header: self.header,
                    max_body: b,
                }
                .frame(&id),
                None => Frame::header(&id, &self.header).into(),
            });
        }
        F::from_fd(fd_body_frame(
            &self.id(FrameType::Body, index),
            msg,
            self.header.len,
            self.body,
            index,
        ))
    }

    fn last_index(&self) -> u16 {
        fd_body_count(self.header.len, self.body)
    }

    /// The header frame; arms the deadline (now + T_ack). Calling it again
    /// restarts the transfer from the header (the one in flight) with a
    /// fresh retry budget.
    pub fn start(&mut self, msg: &[u8], now_ms: u64) -> F {
        self.index = 0;
        self.retx = 0;
        self.body = BodySize::CLASSIC;
        self.state = State::Waiting;
        self.deadline = Some(now_ms + self.ack_timeout_ms as u64);
        self.frame(msg, 0)
    }

    /// An ack frame from the node's receive path. Frames that are not the
    /// expected ack of this transfer (other stream, other type, wrong Q or
    /// index, malformed data, transfer not waiting) give
    /// [`TxStep::Nothing`]. The ack of index 0 must be the 4-byte FD ack
    /// while the FD header is in flight and a classic ack (DLC 2 or 3)
    /// otherwise.
    pub fn on_ack(&mut self, id: &DsorId, data: &[u8], msg: &[u8], now_ms: u64) -> TxStep<F> {
        if self.state != State::Waiting
            || id.ftype != FrameType::Ack
            || id.src != self.dst
            || id.dst != self.src
            || id.chan != self.chan
            || id.seq != self.q_of(self.index)
        {
            return TxStep::Nothing;
        }
        let status = match self.offer {
            Some(offer) if self.index == 0 => match FdAck::decode(data, offer) {
                Some(a) => {
                    if a.status == AckStatus::Ok {
                        self.body = a.body;
                    }
                    a.status
                }
                None => return TxStep::Nothing,
            },
            _ => match Ack::decode(data) {
                Some(a) if a.index == self.index => a.status,
                _ => return TxStep::Nothing,
            },
        };
        let err = match status {
            AckStatus::Ok => None,
            AckStatus::Refused => Some(TxError::Refused),
            AckStatus::NoMemory => Some(TxError::NoMemory),
            AckStatus::TooLong => Some(TxError::TooLong),
        };
        if let Some(e) = err {
            self.state = State::Failed;
            self.deadline = None;
            return TxStep::Failed(e);
        }
        if self.index == self.last_index() {
            self.state = State::Done;
            self.deadline = None;
            return TxStep::Done;
        }
        self.index += 1;
        self.retx = 0;
        self.deadline = Some(now_ms + self.ack_timeout_ms as u64);
        TxStep::Send(self.frame(msg, self.index))
    }

    /// The deadline passed (or maybe not: [`TxStep::Nothing`] if `now_ms`
    /// is before it). Retransmits the frame waited for, or fails with
    /// [`TxError::TimedOut`] after N_retx retransmissions. The first
    /// retransmission of an unanswered FD header is the fallback: the
    /// classic header of the message, same Q.
    pub fn on_timer(&mut self, msg: &[u8], now_ms: u64) -> TxStep<F> {
        match self.deadline {
            Some(d) if self.state == State::Waiting && now_ms >= d => {}
            _ => return TxStep::Nothing,
        }
        if self.retx >= self.max_retx {
            self.state = State::Failed;
            self.deadline = None;
            return TxStep::Failed(TxError::TimedOut);
        }
        self.retx += 1;
        if self.index == 0 && self.offer.is_some() {
            self.offer = None;
            self.fell_back = true;
        }
        self.deadline = Some(now_ms + self.ack_timeout_ms as u64);
        TxStep::Send(self.frame(msg, self.index))
    }

    /// When [`Transfer::on_timer`] must be called next; `None` when not
    /// waiting for an ack.
    pub fn deadline(&self) -> Option<u64> {
        self.deadline
    }

    /// The Q the next message on this stream must use for its header: NOT
    /// the Q of the last frame sent (or `first_q` if nothing was sent).
    pub fn next_q(&self) -> bool {
        if self.state == State::New {
            self.first_q
        } else {
            !self.q_of(self.index)
        }
    }

    /// Whether the last frame of the message (the header if the length is
    /// 0, else the last body) was sent at least once. A
    /// [`TxError::TimedOut`] failure with this true has an unknown outcome.
    /// (An FD header is never the last frame: it is sent only for L > 8.)
    pub fn last_frame_sent(&self) -> bool {
        self.state != State::New
            && self.index == self.last_index()
            && (self.index > 0 || self.offer.is_none())
    }

    /// Whether the transfer ended (success or failure).
    pub fn finished(&self) -> bool {
        matches!(self.state, State::Done | State::Failed)
    }

    /// Whether the sender fell back from the FD to the classic header
    /// (for `FdPeers::on_fallback`).
    pub fn fell_back(&self) -> bool {
        self.fell_back
    }

    /// Whether the receiver acked the FD header (for
    /// `FdPeers::on_fd_ack`).
    pub fn fd_acked(&self) -> bool {
        self.offer.is_some() && self.index > 0
    }

    /// The body size in use (8 until an FD header was acked).
    pub fn body_size(&self) -> BodySize {
        self.body
    }
}

/// Per-destination channel allocator with each stream's remembered
/// sequence bit: 128 nodes x 16 channels, 512 bytes.
#[derive(Clone, Debug)]
pub struct TxStreams {
    busy: [u16; 128],
    q: [u16; 128],
}

impl Default for TxStreams {
    fn default() -> Self {
        Self::new()
    }
}

impl TxStreams {
    /// All channels free, every stream starting with Q = 0.
    pub const fn new() -> Self {
        TxStreams {
            busy: [0; 128],
            q: [0; 128],
        }
    }

    /// Reserve a free channel to `dst`: `(channel, header Q)`, or `None`
    /// if all 16 are in use (or `dst` > 0x7f).
    pub fn alloc(&mut self, dst: u8) -> Option<(u8, bool)> {
        let d = dst as usize;
        if d > MAX_NODE as usize {
            return None;
        }
        let free = !self.busy[d];
        if free == 0 {
            return None;
        }
        let chan = free.trailing_zeros() as u8;
        self.busy[d] |= 1 << chan;
        Some((chan, self.q[d] & (1 << chan) != 0))
    }

    /// Free channel `chan` to `dst`, remembering `next_q`
    /// ([`Transfer::next_q`]) for the stream's next message.
    pub fn release(&mut self, dst: u8, chan: u8, next_q: bool) {
        let d = dst as usize;
        if d > MAX_NODE as usize || chan >= CHANNELS {
            return;
        }
        let bit = 1u16 << chan;
        self.busy[d] &= !bit;
        if next_q {
            self.q[d] |= bit;
        } else {
            self.q[d] &= !bit;
        }
    }

    /// Channels to `dst` in use.
    pub fn in_use(&self, dst: u8) -> u32 {
        self.busy.get(dst as usize).map_or(0, |b| b.count_ones())
    }
}

#[cfg(test)]
mod tests {
    use super::super::dsor_wire::MsgKind;
    use super::*;

    fn ack(t: &Transfer, q: bool, index: u16, st: u8) -> (DsorId, [u8; 3]) {
        let [a, b] = index.to_be_bytes();
        (
            DsorId {
                prio: 0,
                dst: t.src,
                src: t.dst,
                ftype: FrameType::Ack,
                seq: q,
                chan: t.chan,
            },
            [a, b, st],
        )
    }

    #[test]
    fn stop_and_wait() {
        let msg = [1u8, 2, 3, 4, 5, 6, 7, 8, 9];
        let h = Header {
            len: 9,
            kind: MsgKind::Segm { id: 1 },
        };
        let mut t = Transfer::new(5, 3, 5, 0x20, h, true, &Timers::default());
        assert!(t.next_q());
        let f = t.start(&msg, 0);
        assert_eq!(f.id, 0x0400_C295);
        assert_eq!(t.deadline(), Some(100));
        assert_eq!(t.on_timer(&msg, 99), TxStep::Nothing);
        let (id, d) = ack(&t, false, 0, 0);
        assert_eq!(t.on_ack(&id, &d[..2], &msg, 1), TxStep::Nothing);
        let (id, d) = ack(&t, true, 0, 0);
        let TxStep::Send(b1) = t.on_ack(&id, &d[..2], &msg, 1) else {
            panic!()
        };
        assert_eq!(b1.id, 0x0400_C2A5);
        assert!(!t.last_frame_sent());
        assert_eq!(t.on_timer(&msg, 101), TxStep::Send(b1));
        let (id, d) = ack(&t, false, 1, 0);
        let TxStep::Send(b2) = t.on_ack(&id, &d[..2], &msg, 102) else {
            panic!()
        };
        assert_eq!((b2.id, b2.payload()), (0x0400_C2B5, &[9u8][..]));
        assert!(t.last_frame_sent());
        for i in 0..10 {
            assert_eq!(t.on_timer(&msg, 202 + 100 * i), TxStep::Send(b2));
        }
        assert_eq!(t.on_timer(&msg, 1202), TxStep::Failed(TxError::TimedOut));
        assert!(!t.next_q());
        assert_eq!(t.deadline(), None);
    }

    #[test]
    fn refusal_and_streams() {
        let h = Header {
            len: 16,
            kind: MsgKind::Port { dport: 1, sport: 2 },
        };
        let mut s = TxStreams::new();
        let (c, q) = s.alloc(0x0a).unwrap();
        assert_eq!((c, q), (0, false));
        let mut t = Transfer::new(5, 0x0a, 3, 0x40, h, q, &Timers::default());
        let f = t.start(&[0; 16], 0);
        assert_eq!(f.id, 0x0802_8283);
        let (id, d) = ack(&t, false, 0, 1);
        assert_eq!(
            t.on_ack(&id, &d, &[0; 16], 5),
            TxStep::Failed(TxError::Refused)
        );
        s.release(0x0a, c, t.next_q());
        assert_eq!(s.alloc(0x0a), Some((0, true)));
        for i in 1..16 {
            assert_eq!(s.alloc(0x0a), Some((i, false)));
        }
        assert_eq!(s.alloc(0x0a), None);
        assert_eq!(s.alloc(0x80), None);
    }
}

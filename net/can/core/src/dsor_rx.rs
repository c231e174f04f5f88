// SPDX-License-Identifier: GPL-2.0
//! DSOR receiver: the reassembly table of one node (thesis 5.3.3,
//! `canisr_receive_header` and the body/ack handling of
//! `net/can/dsor/protocol.c`; `Documentation/networking/rcan/dsor-wire.rst`,
//! "Receiver").
//!
//! The table has `N` fixed slots, one per (source node, channel) with a
//! state. Buffers are of the caller's type `B` (a kernel vector, a host
//! `Vec<u8>`, ...), obtained from the `accept` callback only for a new
//! header that passed all limits, and handed to the `deliver` callback
//! when the last frame arrives. The last frame is acknowledged only after
//! `deliver` took the message: its ack carries OK if it did, else the
//! status `deliver` refused with (dsor-wire.rst, "Delivery rule"), so a
//! sender's success always means the application has the message.

use super::dsor_wire::{
    fd_body_count, fd_body_frame_len, fd_store_body, Ack, AckStatus, BodySize, DsorId, FdAck,
    FdHeader, Frame, FrameType, Header, Timers, MAX_LEN,
};

/// How a transfer's bodies are framed (dsor-wire.rst, "Message transfer
/// with CAN FD bodies"): `offer` is the B_max of its FD header (`None`
/// for a classic header), `body` the body size chosen (8 for classic).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Fd {
    offer: Option<BodySize>,
    body: BodySize,
}

impl Fd {
    const CLASSIC: Fd = Fd {
        offer: None,
        body: BodySize::CLASSIC,
    };
}

/// Receiver limits (dsor-wire.rst, "Timers and limits").
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Limits {
    /// Largest message length accepted; longer headers get TOO_LONG.
    pub max_len: u16,
    /// Concurrent partial messages from one source node; more get
    /// NO_MEMORY.
    pub max_per_peer: u8,
    /// Sum of the lengths of all partial messages; more gets NO_MEMORY.
    pub max_bytes_total: usize,
}

impl Limits {
    /// 65535 bytes, 16 per peer, 1 MiB in total.
    pub const DEFAULT: Limits = Limits {
        max_len: MAX_LEN as u16,
        max_per_peer: 16,
        max_bytes_total: 1 << 20,
    };
}

impl Default for Limits {
    fn default() -> Self {
        Limits::DEFAULT
    }
}

/// A new message the receiver is asked to accept.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Incoming<'a> {
    /// Source node.
    pub src: u8,
    /// Priority of the header frame.
    pub prio: u8,
    /// The header.
    pub header: &'a Header,
}

/// A completely received message.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Delivered<B> {
    /// Source node.
    pub src: u8,
    /// Priority of the header frame.
    pub prio: u8,
    /// The header.
    pub header: Header,
    /// The buffer from `accept`, all `header.len` bytes filled.
    pub buf: B,
}

/// Result of one received frame.
#[derive(Debug)]
pub struct RxOutput<B> {
    /// Ack to send (29-bit identifier, no `CAN_EFF_FLAG`).
    pub ack: Option<Frame>,
    /// Message completed by this frame and taken by the application (at
    /// most once per message). Only [`Reassembler::on_frame`] fills it;
    /// with [`Reassembler::on_frame_with`] the `deliver` callback gets it.
    pub delivered: Option<Delivered<B>>,
    /// A new header that this frame made the receiver refuse, with the
    /// status of its ack (not set for a repeated answer to a duplicate).
    pub header_refused: Option<AckStatus>,
}

impl<B> RxOutput<B> {
    const NONE: RxOutput<B> = RxOutput {
        ack: None,
        delivered: None,
        header_refused: None,
    };

    fn ack(ack: Option<Frame>) -> Self {
        RxOutput {
            ack,
            delivered: None,
            header_refused: None,
        }
    }
}

#[derive(Debug)]
enum St<B> {
    Free,
    Receiving {
        header: Header,
        fd: Fd,
        hq: bool,
        prio: u8,
        /// Next expected body index, 1..=n.
        next: u16,
        buf: B,
    },
    /// A partial message the application no longer wants
    /// ([`Reassembler::refuse_partial`]): no buffer; body `next` gets
    /// `status` and ends the transfer (Done); repetitions of frames acked
    /// before are re-acked OK as in Receiving.
    Refusing {
        header: Header,
        fd: Fd,
        hq: bool,
        next: u16,
        status: AckStatus,
    },
    /// The last acked frame was `last_index` (Q `last_q`), answered with
    /// `status`: OK, or the refusal of the header (index 0) or of a body.
    Done {
        header: Header,
        fd: Fd,
        hq: bool,
        last_q: bool,
        last_index: u16,
        status: AckStatus,
    },
}

#[derive(Debug)]
struct Slot<B> {
    src: u8,
    chan: u8,
    deadline: u64,
    st: St<B>,
}

impl<B> Slot<B> {
    const FREE: Slot<B> = Slot {
        src: 0,
        chan: 0,
        deadline: 0,
        st: St::Free,
    };

    fn is_free(&self) -> bool {
        matches!(self.st, St::Free)
    }

    fn is(&self, src: u8, chan: u8) -> bool {
        !self.is_free() && self.src == src && self.chan == chan
    }
}

/// The reassembly table of node `local` with `N` slots.
#[derive(Debug)]
pub struct Reassembler<B: AsMut<[u8]>, const N: usize> {
    local: u8,
    limits: Limits,
    /// Largest body size accepted from FD headers; `None`: FD headers are
    /// ignored (a classic receiver).
    fd_max: Option<BodySize>,
    reasm_ms: u64,
    slots: [Slot<B>; N],
}

fn ack_frame(id: &DsorId, index: u16, status: AckStatus) -> Option<Frame> {
    Some(Frame::ack(&id.ack_id(), &Ack { index, status }))
}

/// The ack of a header: classic (DLC 2 or 3), or for an FD header the
/// 4-byte ack with the chosen body size (8 with a refusal).
fn header_ack(id: &DsorId, status: AckStatus, fd: &Fd) -> Option<Frame> {
    if fd.offer.is_none() {
        return ack_frame(id, 0, status);
    }
    let body = match status {
        AckStatus::Ok => fd.body,
        _ => BodySize::CLASSIC,
    };
    Some(FdAck { status, body }.frame(&id.ack_id()))
}

/// The Q bit body `next` of a message whose header had Q `hq` carries:
/// Q alternates from the header on.
fn expected_q(hq: bool, next: u16) -> bool {
    hq ^ (next & 1 == 1)
}

/// A body whose Q is not the expected one, for a message of `len` bytes
/// whose next body is `next`: a retransmission of body `next - 1` whose
/// ack was lost (none if `next == 1`). It gets its old answer (OK) again,
/// so that the sender moves on, and keeps the slot alive until `deadline`;
/// anything else is ignored.
fn previous_body_again<B>(
    id: &DsorId,
    data: &[u8],
    len: u16,
    b: BodySize,
    next: u16,
    deadline: u64,
    slot_deadline: &mut u64,
) -> RxOutput<B> {
    if next < 2 || data.len() != fd_body_frame_len(len, b, next - 1) as usize {
        return RxOutput::NONE;
    }
    *slot_deadline = deadline;
    RxOutput::ack(ack_frame(id, next - 1, AckStatus::Ok))
}

/// `status` as a refusal: OK means REFUSED.
fn refusal(status: AckStatus) -> AckStatus {
    match status {
        AckStatus::Ok => AckStatus::Refused,
        s => s,
    }
}

impl<B: AsMut<[u8]>, const N: usize> Reassembler<B, N> {
    /// An empty table for node `local`.
    pub const fn new(local: u8, limits: Limits, timers: &Timers) -> Self {
        Reassembler {
            local,
            limits,
            fd_max: None,
            reasm_ms: timers.reasm_timeout_ms as u64,
            slots: [Slot::FREE; N],
        }
    }

    /// The node this table receives for.
    pub fn local(&self) -> u8 {
        self.local
    }

    /// The largest body size taken from FD headers; `None`: FD headers are
    /// ignored.
    pub fn fd_body_size(&self) -> Option<BodySize> {
        self.fd_max
    }

    /// Take FD headers (dsor-wire.rst, "Message transfer with CAN FD
    /// bodies"), choosing body sizes up to `max` (8: answer FD headers but
    /// ask for classic bodies); `None` (the default) ignores FD headers as
    /// a classic receiver does. Only for a node on a CAN FD interface.
    /// Transfers already started keep their body size.
    pub fn set_fd_body_size(&mut self, max: Option<BodySize>) {
        self.fd_max = max;
    }

    /// The limits in force.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Change the limits (applies to headers received from now on).
    pub fn set_limits(&mut self, limits: Limits) {
        self.limits = limits;
    }

    fn find(&self, src: u8, chan: u8) -> Option<usize> {
        self.slots.iter().position(|s| s.is(src, chan))
    }

    /// The oldest Done state (the one to reuse when no slot is free).
    fn oldest_done(&self) -> Option<usize> {
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, s)| matches!(s.st, St::Done { .. }))
            .min_by_key(|(_, s)| s.deadline)
            .map(|(i, _)| i)
    }

    /// One received frame (29-bit identifier already split; `data` is the
    /// DLC bytes), for an application that always takes a completed
    /// message: it is returned in [`RxOutput::delivered`]. See
    /// [`Reassembler::on_frame_with`].
    pub fn on_frame<F: FnMut(&Incoming<'_>) -> Result<B, AckStatus>>(
        &mut self,
        id: &DsorId,
        data: &[u8],
        now_ms: u64,
        accept: F,
    ) -> RxOutput<B> {
        let mut got = None;
        let mut out = self.on_frame_with(id, data, now_ms, accept, |d| {
            got = Some(d);
            Ok(())
        });
        out.delivered = got;
        out
    }

    /// One received frame (29-bit identifier already split; `data` is the
    /// DLC bytes). Frames not addressed to the local node, acks, reserved
    /// and malformed frames give nothing. `accept` is called only for a
    /// new message header that passed the limits; it returns a buffer of
    /// exactly `header.len` bytes (any other length counts as NO_MEMORY)
    /// or the status to refuse with. `deliver` is called once per message,
    /// with the last frame (the header if the length is 0, else the last
    /// body), before that frame is acked: `Ok` acks it OK, `Err(status)`
    /// acks it with `status` (`Err(AckStatus::Ok)` counts as REFUSED) and
    /// the message is not delivered. Either answer is remembered and
    /// repeated for retransmissions of that frame.
    pub fn on_frame_with<F, D>(
        &mut self,
        id: &DsorId,
        data: &[u8],
        now_ms: u64,
        accept: F,
        deliver: D,
    ) -> RxOutput<B>
    where
        F: FnMut(&Incoming<'_>) -> Result<B, AckStatus>,
        D: FnOnce(Delivered<B>) -> Result<(), AckStatus>,
    {
        if id.dst != self.local {
            return RxOutput::NONE;
        }
        match id.ftype {
            FrameType::Header => self.on_header(id, data, now_ms, accept, deliver),
            FrameType::Body => self.on_body(id, data, now_ms, deliver),
            FrameType::Ack => RxOutput::NONE,
        }
    }

    /// Stops reassembling every partial message for which `keep` returns
    /// false (for example: the last socket that wanted it was closed). Its
    /// buffer is dropped now; the next body of the transfer is answered
    /// with `status` instead of OK, which ends the transfer at the sender
    /// (retransmissions of the header or body acked before are still
    /// re-acked OK, so that the sender gets to that body).
    /// `AckStatus::Ok` counts as REFUSED. Returns how many were stopped.
    pub fn refuse_partial<K: FnMut(&Incoming<'_>) -> bool>(
        &mut self,
        mut keep: K,
        status: AckStatus,
    ) -> usize {
        let status = refusal(status);
        let mut n = 0;
        for s in self.slots.iter_mut() {
            let (header, fd, hq, next) = match &s.st {
                St::Receiving {
                    header,
                    fd,
                    hq,
                    prio,
                    next,
                    ..
                } => {
                    let inc = Incoming {
                        src: s.src,
                        prio: *prio,
                        header,
                    };
                    if keep(&inc) {
                        continue;
                    }
                    (*header, *fd, *hq, *next)
                }
                _ => continue,
            };
            s.st = St::Refusing {
                header,
                fd,
                hq,
                next,
                status,
            };
            n += 1;
        }
        n
    }

    fn on_header<F, D>(
        &mut self,
        id: &DsorId,
        data: &[u8],
        now_ms: u64,
        mut accept: F,
        deliver: D,
    ) -> RxOutput<B>
    where
        F: FnMut(&Incoming<'_>) -> Result<B, AckStatus>,
        D: FnOnce(Delivered<B>) -> Result<(), AckStatus>,
    {
        let (h, fd) = if data.len() == FdHeader::LEN {
            match (self.fd_max, FdHeader::decode(data)) {
                (Some(max), Some(f)) => (
                    f.header,
                    Fd {
                        offer: Some(f.max_body),
                        body: f.max_body.min(max),
                    },
                ),
                _ => return RxOutput::NONE,
            }
        } else {
            match Header::decode(data) {
                Some(h) => (h, Fd::CLASSIC),
                None => return RxOutput::NONE,
            }
        };
        let deadline = now_ms + self.reasm_ms;
        let existing = self.find(id.src, id.chan);
        if let Some(i) = existing {
            let slot = &mut self.slots[i];
            // An FD header and a classic one are never duplicates of each
            // other; a duplicate gets the body size chosen before.
            let dup = match slot.st {
                St::Receiving {
                    header,
                    fd: f,
                    hq,
                    next,
                    ..
                } if next == 1 && hq == id.seq && header == h && f.offer == fd.offer => {
                    Some((AckStatus::Ok, f))
                }
                St::Done {
                    header,
                    fd: f,
                    hq,
                    last_index: 0,
                    status,
                    ..
                } if hq == id.seq && header == h && f.offer == fd.offer => Some((status, f)),
                // Acked OK before; the refusal goes with body 1.
                St::Refusing {
                    header,
                    fd: f,
                    hq,
                    next,
                    ..
                } if next == 1 && hq == id.seq && header == h && f.offer == fd.offer => {
                    Some((AckStatus::Ok, f))
                }
                _ => None,
            };
            if let Some((status, f)) = dup {
                slot.deadline = deadline;
                return RxOutput::ack(header_ack(id, status, &f));
            }
            // A new message on this stream: drop whatever was there.
            slot.st = St::Free;
        }
        let peer = self
            .slots
            .iter()
            .filter(|s| s.src == id.src && matches!(s.st, St::Receiving { .. }))
            .count();
        // A refusal is remembered in a free slot (or the stream's own); an
        // accepted message may also take the slot of the oldest Done state.
        let free = existing.or_else(|| self.slots.iter().position(|s| s.is_free()));
        let slot = free.or_else(|| self.oldest_done());
        let mut got = None;
        let mut status = if h.len > self.limits.max_len {
            AckStatus::TooLong
        } else if peer >= self.limits.max_per_peer as usize
            || self.bytes_in_use() + h.len as usize > self.limits.max_bytes_total
            || slot.is_none()
        {
            AckStatus::NoMemory
        } else {
            let inc = Incoming {
                src: id.src,
                prio: id.prio,
                header: &h,
            };
            match accept(&inc) {
                Ok(mut b) => {
                    if b.as_mut().len() == h.len as usize {
                        got = Some(b);
                        AckStatus::Ok
                    } else {
                        AckStatus::NoMemory
                    }
                }
                Err(s) => refusal(s),
            }
        };
        let header_refused = (status != AckStatus::Ok).then_some(status);
        // A zero-length message is complete with its header: it is
        // delivered before the header is acked, and the ack says whether
        // the application took it.
        let mut delivered = false;
        if h.len == 0 {
            if let Some(buf) = got.take() {
                let d = Delivered {
                    src: id.src,
                    prio: id.prio,
                    header: h,
                    buf,
                };
                status = match deliver(d) {
                    Ok(()) => AckStatus::Ok,
                    Err(s) => refusal(s),
                };
                delivered = true;
            }
        }
        let out = RxOutput {
            ack: header_ack(id, status, &fd),
            delivered: None,
            header_refused,
        };
        let slot = if got.is_some() || delivered {
            slot
        } else {
            free
        };
        let Some(i) = slot else {
            // No slot to remember the refusal in.
            return out;
        };
        let slot = &mut self.slots[i];
        slot.src = id.src;
        slot.chan = id.chan;
        slot.deadline = deadline;
        slot.st = match got {
            Some(buf) => St::Receiving {
                header: h,
                fd,
                hq: id.seq,
                prio: id.prio,
                next: 1,
                buf,
            },
            None => St::Done {
                header: h,
                fd,
                hq: id.seq,
                last_q: id.seq,
                last_index: 0,
                status,
            },
        };
        out
    }

    fn on_body<D>(&mut self, id: &DsorId, data: &[u8], now_ms: u64, deliver: D) -> RxOutput<B>
    where
        D: FnOnce(Delivered<B>) -> Result<(), AckStatus>,
    {
        let Some(i) = self.find(id.src, id.chan) else {
            return RxOutput::NONE;
        };
        let deadline = now_ms + self.reasm_ms;
        let slot = &mut self.slots[i];
        // While refusing or receiving, a body with the other Q than the
        // next one's is the previous body again (or nothing).
        if let St::Refusing {
            header,
            fd,
            hq,
            next,
            ..
        }
        | St::Receiving {
            header,
            fd,
            hq,
            next,
            ..
        } = &slot.st
        {
            if id.seq != expected_q(*hq, *next) {
                let (len, b, next) = (header.len, fd.body, *next);
                return previous_body_again(id, data, len, b, next, deadline, &mut slot.deadline);
            }
        }
        match &mut slot.st {
            St::Free => RxOutput::NONE,
            St::Done {
                header,
                fd,
                last_q,
                last_index,
                status,
                ..
            } => {
                if *last_index == 0
                    || id.seq != *last_q
                    || data.len() != fd_body_frame_len(header.len, fd.body, *last_index) as usize
                {
                    return RxOutput::NONE;
                }
                slot.deadline = deadline;
                // The last body again: the same answer as before.
                RxOutput::ack(ack_frame(id, *last_index, *status))
            }
            St::Refusing {
                header,
                fd,
                hq,
                next,
                status,
            } => {
                // Frames acked before got their old answer (OK) above, so
                // that a sender that missed that ack moves on; the first
                // new frame (body `next`) gets the refusal.
                let k = *next;
                if data.len() != fd_body_frame_len(header.len, fd.body, k) as usize {
                    return RxOutput::NONE;
                }
                let status = *status;
                slot.st = St::Done {
                    header: *header,
                    fd: *fd,
                    hq: *hq,
                    last_q: id.seq,
                    last_index: k,
                    status,
                };
                slot.deadline = deadline;
                RxOutput::ack(ack_frame(id, k, status))
            }
            St::Receiving {
                header,
                fd,
                hq,
                next,
                buf,
                ..
            } => {
                let k = *next;
                // Checks the length (malformed: nothing stored); the
                // buffer has header.len bytes, so it always fits.
                if fd_store_body(buf.as_mut(), header.len, fd.body, k, data).is_none() {
                    return RxOutput::NONE;
                }
                slot.deadline = deadline;
                if k < fd_body_count(header.len, fd.body) {
                    *next = k + 1;
                    return RxOutput::ack(ack_frame(id, k, AckStatus::Ok));
                }
                let h = *header;
                let hq = *hq;
                let placeholder = St::Done {
                    header: h,
                    fd: *fd,
                    hq,
                    last_q: id.seq,
                    last_index: k,
                    status: AckStatus::Ok,
                };
                let St::Receiving { prio, buf, .. } = core::mem::replace(&mut slot.st, placeholder)
                else {
                    // Cannot happen: matched above.
                    return RxOutput::NONE;
                };
                // The last body: hand the message over first, then ack
                // with the application's answer.
                let status = match deliver(Delivered {
                    src: id.src,
                    prio,
                    header: h,
                    buf,
                }) {
                    Ok(()) => AckStatus::Ok,
                    Err(s) => refusal(s),
                };
                if let St::Done { status: st, .. } = &mut slot.st {
                    *st = status;
                }
                RxOutput::ack(ack_frame(id, k, status))
            }
        }
    }

    /// Free every state whose deadline is at or before `now_ms`; returns how
    /// many partial messages were dropped (their buffers are dropped).
    pub fn on_timer(&mut self, now_ms: u64) -> usize {
        let mut dropped = 0;
        for s in self.slots.iter_mut() {
            if !s.is_free() && s.deadline <= now_ms {
                if matches!(s.st, St::Receiving { .. }) {
                    dropped += 1;
                }
                s.st = St::Free;
            }
        }
        dropped
    }

    /// The earliest deadline of any state, if any.
    pub fn next_deadline(&self) -> Option<u64> {
        self.slots
            .iter()
            .filter(|s| !s.is_free())
            .map(|s| s.deadline)
            .min()
    }

    /// Drop every state and buffer; returns how many partial messages
    /// were dropped.
    pub fn clear(&mut self) -> usize {
        let dropped = self.active();
        for s in self.slots.iter_mut() {
            s.st = St::Free;
        }
        dropped
    }

    /// Bytes of reassembly buffers held (sum of the lengths of the partial
    /// messages).
    pub fn bytes_in_use(&self) -> usize {
        self.slots
            .iter()
            .map(|s| match s.st {
                St::Receiving { header, .. } => header.len as usize,
                _ => 0,
            })
            .sum()
    }

    /// Number of partial messages being reassembled.
    pub fn active(&self) -> usize {
        self.slots
            .iter()
            .filter(|s| matches!(s.st, St::Receiving { .. }))
            .count()
    }

    /// Number of slots in use (partial messages and remembered completed or
    /// refused transfers).
    pub fn states(&self) -> usize {
        self.slots.iter().filter(|s| !s.is_free()).count()
    }
}

#[cfg(test)]
mod tests {
    use super::super::dsor_wire::MsgKind;
    use super::*;

    type Rx = Reassembler<[u8; 9], 2>;

    fn id(ftype: FrameType, seq: bool, dst: u8) -> DsorId {
        DsorId {
            prio: 7,
            dst,
            src: 4,
            ftype,
            seq,
            chan: 1,
        }
    }

    fn ack_of(out: &RxOutput<[u8; 9]>) -> Option<(bool, Ack)> {
        let f = out.ack?;
        let i = DsorId::from_can_id(f.id)?;
        assert_eq!(
            (i.src, i.dst, i.chan, i.prio, i.ftype),
            (2, 4, 1, 7, FrameType::Ack)
        );
        Some((i.seq, Ack::decode(f.payload())?))
    }

    #[test]
    fn every_unexpected_frame() {
        let tm = Timers::default();
        let mut rx = Rx::new(2, Limits::default(), &tm);
        let h = Header {
            len: 9,
            kind: MsgKind::Port { dport: 1, sport: 2 },
        };
        let mut hb = [0; 8];
        let dlc = h.encode(&mut hb) as usize;
        let ok = |i| {
            Some((
                false,
                Ack {
                    index: i,
                    status: AckStatus::Ok,
                },
            ))
        };
        let acc = |_: &Incoming<'_>| Ok([0u8; 9]);
        // Body with no transfer, ack, other destination, bad header DLC.
        assert!(ack_of(&rx.on_frame(&id(FrameType::Body, true, 2), &[1; 8], 0, acc)).is_none());
        assert!(ack_of(&rx.on_frame(&id(FrameType::Ack, false, 2), &[0, 0], 0, acc)).is_none());
        assert!(
            ack_of(&rx.on_frame(&id(FrameType::Header, false, 3), &hb[..dlc], 0, acc)).is_none()
        );
        assert!(ack_of(&rx.on_frame(&id(FrameType::Header, false, 2), &hb[..5], 0, acc)).is_none());
        assert_eq!(rx.states(), 0);
        // Header (Q 0), its duplicate, then body 1 must have Q 1.
        let hdr = id(FrameType::Header, false, 2);
        assert_eq!(ack_of(&rx.on_frame(&hdr, &hb[..dlc], 0, acc)), ok(0));
        assert_eq!(ack_of(&rx.on_frame(&hdr, &hb[..dlc], 1, acc)), ok(0));
        assert!(ack_of(&rx.on_frame(&id(FrameType::Body, false, 2), &[1; 8], 2, acc)).is_none());
        assert!(ack_of(&rx.on_frame(&id(FrameType::Body, true, 2), &[1; 7], 2, acc)).is_none());
        let b1 = id(FrameType::Body, true, 2);
        let o = rx.on_frame(&b1, &[1; 8], 3, acc);
        assert_eq!(ack_of(&o).map(|a| a.1.index), Some(1));
        // The header is no longer a duplicate once body 1 arrived, and a
        // repeated body 1 is re-acked without being stored again.
        let o = rx.on_frame(&b1, &[9; 8], 4, acc);
        assert_eq!(ack_of(&o).map(|a| a.1.index), Some(1));
        assert!(ack_of(&rx.on_frame(&id(FrameType::Body, false, 2), &[2; 2], 5, acc)).is_none());
        let o = rx.on_frame(&id(FrameType::Body, false, 2), &[2], 5, acc);
        assert_eq!(ack_of(&o), ok(2));
        let d = o.delivered.unwrap();
        assert_eq!((d.src, d.prio, d.buf), (4, 7, [1, 1, 1, 1, 1, 1, 1, 1, 2]));
        // Done: last body re-acked, nothing delivered; others ignored.
        let o = rx.on_frame(&id(FrameType::Body, false, 2), &[2], 6, acc);
        assert_eq!((ack_of(&o), o.delivered.is_none()), (ok(2), true));
        assert!(ack_of(&rx.on_frame(&b1, &[1; 8], 6, acc)).is_none());
        assert_eq!(rx.active(), 0);
        assert_eq!(rx.next_deadline(), Some(2006));
        assert_eq!(rx.on_timer(2006), 0);
        assert_eq!(rx.states(), 0);
        // A partial message times out.
        rx.on_frame(&hdr, &hb[..dlc], 10, acc);
        assert_eq!((rx.active(), rx.bytes_in_use()), (1, 9));
        assert_eq!(rx.on_timer(2009), 0);
        assert_eq!(rx.on_timer(2010), 1);
        assert_eq!(rx.bytes_in_use(), 0);
    }

    fn status_of(out: &RxOutput<[u8; 9]>) -> Option<(u16, AckStatus)> {
        ack_of(out).map(|(_, a)| (a.index, a.status))
    }

    /// The delivery rule: the last frame is acked with the application's
    /// answer, which is remembered for its retransmissions.
    #[test]
    fn last_frame_acked_with_the_applications_answer() {
        let tm = Timers::default();
        let mut rx = Rx::new(2, Limits::default(), &tm);
        let h = Header {
            len: 9,
            kind: MsgKind::Segm { id: 1 },
        };
        let mut hb = [0; 8];
        let dlc = h.encode(&mut hb) as usize;
        let acc = |_: &Incoming<'_>| Ok([0u8; 9]);
        let hdr = id(FrameType::Header, false, 2);
        let b1 = id(FrameType::Body, true, 2);
        let b2 = id(FrameType::Body, false, 2);
        let full = |_: Delivered<[u8; 9]>| Err(AckStatus::NoMemory);
        let o = rx.on_frame_with(&hdr, &hb[..dlc], 0, acc, full);
        assert_eq!(status_of(&o), Some((0, AckStatus::Ok)));
        let o = rx.on_frame_with(&b1, &[1; 8], 1, acc, full);
        assert_eq!(status_of(&o), Some((1, AckStatus::Ok)));
        let mut offered = 0;
        let o = rx.on_frame_with(&b2, &[2], 2, acc, |d| {
            offered += 1;
            assert_eq!(d.buf, [1, 1, 1, 1, 1, 1, 1, 1, 2]);
            Err(AckStatus::NoMemory)
        });
        assert_eq!(status_of(&o), Some((2, AckStatus::NoMemory)));
        assert_eq!((offered, o.header_refused), (1, None));
        // The retransmission gets the same answer; the application is not
        // asked again.
        let o = rx.on_frame_with(&b2, &[2], 3, acc, |_| -> Result<(), AckStatus> {
            panic!("offered twice")
        });
        assert_eq!(status_of(&o), Some((2, AckStatus::NoMemory)));
        assert_eq!((rx.active(), rx.bytes_in_use()), (0, 0));
        // A zero-length message: the header is the last frame.
        let mut rx = Reassembler::<Vec<u8>, 4>::new(2, Limits::default(), &tm);
        let vacc = |i: &Incoming<'_>| Ok(vec![0u8; usize::from(i.header.len)]);
        let z = Header {
            len: 0,
            kind: MsgKind::Segm { id: 2 },
        };
        let mut zb = [0; 8];
        let zdlc = z.encode(&mut zb) as usize;
        let zack = |o: &RxOutput<Vec<u8>>| {
            let a = Ack::decode(o.ack.unwrap().payload()).unwrap();
            (a.index, a.status)
        };
        let o = rx.on_frame_with(&hdr, &zb[..zdlc], 4, vacc, |_| Err(AckStatus::Ok));
        assert_eq!(zack(&o), (0, AckStatus::Refused));
        let o = rx.on_frame_with(&hdr, &zb[..zdlc], 5, vacc, |_| -> Result<(), AckStatus> {
            panic!("offered twice")
        });
        assert_eq!(zack(&o), (0, AckStatus::Refused));
        // The old entry point delivers and acks OK.
        let hdr3 = DsorId { chan: 3, ..hdr };
        let o = rx.on_frame(&hdr3, &zb[..zdlc], 6, vacc);
        assert_eq!(zack(&o), (0, AckStatus::Ok));
        assert!(o.delivered.is_some());
    }

    /// A partial message whose application went away: its buffer is freed
    /// at once, repeated frames are re-acked OK, the next body is refused.
    #[test]
    fn refuse_partial_refuses_the_next_body() {
        let tm = Timers::default();
        let mut rx = Reassembler::<[u8; 17], 2>::new(2, Limits::default(), &tm);
        let h = Header {
            len: 17,
            kind: MsgKind::Port { dport: 1, sport: 2 },
        };
        let mut hb = [0; 8];
        let dlc = h.encode(&mut hb) as usize;
        let acc = |_: &Incoming<'_>| Ok([0u8; 17]);
        let never = |_: Delivered<[u8; 17]>| -> Result<(), AckStatus> { panic!("delivered") };
        let st = |o: &RxOutput<[u8; 17]>| {
            o.ack
                .map(|f| Ack::decode(f.payload()).unwrap())
                .map(|a| (a.index, a.status))
        };
        let hdr = id(FrameType::Header, false, 2);
        assert_eq!(
            st(&rx.on_frame_with(&hdr, &hb[..dlc], 0, acc, never)),
            Some((0, AckStatus::Ok))
        );
        // Keep it: nothing changes.
        assert_eq!(rx.refuse_partial(|_| true, AckStatus::Refused), 0);
        assert_eq!(rx.bytes_in_use(), 17);
        let mut seen = None;
        let n = rx.refuse_partial(
            |inc| {
                seen = Some((inc.src, inc.prio, *inc.header));
                false
            },
            AckStatus::Refused,
        );
        assert_eq!((n, seen), (1, Some((4, 7, h))));
        assert_eq!((rx.active(), rx.bytes_in_use(), rx.states()), (0, 0, 1));
        // The header again (its ack was lost): OK, as before.
        assert_eq!(
            st(&rx.on_frame_with(&hdr, &hb[..dlc], 1, acc, never)),
            Some((0, AckStatus::Ok))
        );
        // Body 1 is refused; its retransmission gets the same answer.
        let b1 = id(FrameType::Body, true, 2);
        assert_eq!(
            st(&rx.on_frame_with(&b1, &[1; 8], 2, acc, never)),
            Some((1, AckStatus::Refused))
        );
        assert_eq!(
            st(&rx.on_frame_with(&b1, &[1; 8], 3, acc, never)),
            Some((1, AckStatus::Refused))
        );
        assert!(
            st(&rx.on_frame_with(&id(FrameType::Body, false, 2), &[1; 8], 3, acc, never)).is_none()
        );
        // Refused after body 1 was stored: body 1 again is re-acked OK,
        // body 2 refused with the given status.
        let mut rx = Reassembler::<[u8; 17], 2>::new(2, Limits::default(), &tm);
        rx.on_frame_with(&hdr, &hb[..dlc], 0, acc, never);
        rx.on_frame_with(&b1, &[1; 8], 1, acc, never);
        assert_eq!(rx.refuse_partial(|_| false, AckStatus::NoMemory), 1);
        assert_eq!(
            st(&rx.on_frame_with(&b1, &[1; 8], 2, acc, never)),
            Some((1, AckStatus::Ok))
        );
        let b2 = id(FrameType::Body, false, 2);
        assert!(st(&rx.on_frame_with(&b2, &[1; 7], 3, acc, never)).is_none());
        assert_eq!(
            st(&rx.on_frame_with(&b2, &[1; 8], 3, acc, never)),
            Some((2, AckStatus::NoMemory))
        );
        // The state expires like any other.
        assert_eq!(rx.on_timer(3 + 2000), 0);
        assert_eq!(rx.states(), 0);
    }
}

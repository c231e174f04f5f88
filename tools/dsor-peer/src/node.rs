// SPDX-License-Identifier: GPL-2.0
//! One DSOR node: the stop-and-wait sender and the reassembling receiver
//! (Documentation/networking/rcan/dsor-wire.rst; thesis 5.3.3), with no I/O.
//!
//! The caller feeds received frames ([`Node::on_frame`]) and the time
//! ([`Node::poll`]), and takes out frames to transmit ([`Node::pop_frame`])
//! and events ([`Node::pop_event`]). Time is a number of milliseconds from
//! any origin, so tests run on a virtual clock.

use crate::wire::{
    bodies_of, body_frame_len, body_payload, Ack, FdAck, FdHeader, Frame, Header, Id, Kind, Status,
    Type, FD_LONG_LENS,
};
use std::collections::{HashMap, VecDeque};

/// Protocol parameters.
#[derive(Clone, Debug)]
pub struct Config {
    /// Own node number 0..=0x7f.
    pub node: u8,
    /// T_ack: wait for an ack this long before retransmitting (ms).
    pub t_ack: u64,
    /// N_retx: retransmissions of one frame before the message fails.
    pub n_retx: u32,
    /// T_reasm: a partial message without progress, and the record of a
    /// finished one, are kept this long (ms).
    pub t_reasm: u64,
    /// Longest message accepted; longer headers are answered TOO_LONG.
    pub max_len: u16,
    /// Concurrent reassemblies per source node; more are answered NO_MEMORY.
    pub max_per_peer: usize,
    /// Bytes of reassembly buffers in total; more are answered NO_MEMORY.
    pub max_bytes_total: usize,
    /// Answer every header REFUSED.
    pub refuse: bool,
    /// The receiving application holds at most this many messages and
    /// never reads them (a full receive queue): a complete message beyond
    /// that is refused with its last frame, NO_MEMORY (dsor-wire.rst,
    /// "Delivery rule").
    pub app_queue: Option<usize>,
    /// The receiving application goes away after this many new body
    /// frames were received: partial messages are refused at their next
    /// body, new headers and complete messages REFUSED.
    pub close_after_frames: Option<u64>,
    /// The receiving application goes away this many ms after the first
    /// header it accepted (same effect as `close_after_frames`).
    pub close_after_ms: Option<u64>,
    /// The interface is in CAN FD mode and the node implements the FD
    /// extension (dsor-wire.rst, "Message transfer with CAN FD bodies"):
    /// it offers FD bodies for messages longer than 8 bytes and takes
    /// them. False: a classic node, which ignores FD frames.
    pub fd: bool,
    /// The largest body size offered (B_max) and accepted: 12, 16, 20,
    /// 24, 32, 48 or 64.
    pub fd_b_max: u8,
}

impl Config {
    /// The spec's defaults for node `node`.
    pub fn new(node: u8) -> Config {
        Config {
            node,
            t_ack: 100,
            n_retx: 10,
            t_reasm: 2000,
            max_len: 65535,
            max_per_peer: 16,
            max_bytes_total: 16 * 65535,
            refuse: false,
            app_queue: None,
            close_after_frames: None,
            close_after_ms: None,
            fd: false,
            fd_b_max: 64,
        }
    }
}

/// Why a message failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Fail {
    /// No matching ack after N_retx retransmissions (ETIMEDOUT).
    Timeout,
    /// Ack status REFUSED (ECONNREFUSED).
    Refused,
    /// Ack status NO_MEMORY (ENOBUFS).
    NoMemory,
    /// Ack status TOO_LONG (EMSGSIZE), or longer than 65535 bytes.
    TooLong,
}

impl Fail {
    /// The word printed after `reason=`.
    pub fn reason(&self) -> &'static str {
        match self {
            Fail::Timeout => "timeout",
            Fail::Refused => "refused",
            Fail::NoMemory => "nomem",
            Fail::TooLong => "toolong",
        }
    }
}

/// A message the receiver delivered.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Delivery {
    /// Source node.
    pub src: u8,
    /// The header's priority.
    pub prio: u8,
    /// Channel it came on.
    pub chan: u8,
    /// Addressing.
    pub kind: Kind,
    /// The message.
    pub payload: Vec<u8>,
}

/// What happened.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum Event {
    /// A complete message arrived (exactly once per message).
    Delivered(Delivery),
    /// The application could not take a message: complete but refused
    /// with its last frame, or a partial one refused because the
    /// application went away (`payload` holds what had arrived).
    NotDelivered {
        /// The message as far as received.
        msg: Delivery,
        /// The status its sender was answered with.
        status: Status,
    },
    /// A message this node sent finished.
    Sent {
        /// The handle [`Node::send`] returned.
        handle: u64,
        /// Success or why not.
        result: Result<(), Fail>,
        /// Whether the last frame of the message was ever transmitted
        /// (a failure with `false` means the receiver cannot have it).
        last_frame_sent: bool,
    },
}

/// Why [`Node::send`] refused to start a message.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum SendError {
    /// All 16 channels to this destination are busy.
    Busy,
    /// Longer than 65535 bytes.
    TooLong,
    /// Destination node above 0x7f.
    BadNode,
}

/// What the sender knows of a destination node (dsor-wire.rst,
/// "Sender"): it acked an FD header, or the sender fell back to the
/// classic header for it. Unknown nodes are offered FD bodies.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum PeerMode {
    Fd,
    Classic,
}

/// A message being sent on one (dst, channel).
struct TxTransfer {
    handle: u64,
    prio: u8,
    header: Header,
    /// The header sent (and to send again) is the FD header; cleared by
    /// the fallback to the classic header.
    fd_offer: bool,
    /// Body size: 8 (classic bodies) until an FD header's ack chose another.
    b: u8,
    len: u16,
    payload: Vec<u8>,
    /// Frame awaiting its ack: 0 header, k body k.
    index: u16,
    q: bool,
    /// Transmissions of the current frame so far.
    sent: u32,
    deadline: u64,
}

/// Receiver state of one (src, channel); no entry = Idle.
enum RxState {
    Receiving {
        prio: u8,
        hdr_q: bool,
        /// The header's bytes (an FD header's in canonical form, so that
        /// duplicates compare equal whatever their reserved bytes; 12
        /// bytes only for an FD header, whose duplicates get the 4-byte ack).
        hdr: Vec<u8>,
        /// Body size: 8 after a classic header, the chosen B after an FD one.
        b: u8,
        kind: Kind,
        len: u16,
        buf: Vec<u8>,
        /// Index of the body expected next (1..=n).
        next: u16,
        expect_q: bool,
        deadline: u64,
        /// The application went away: body `next` is answered with this
        /// status (the buffer is already freed).
        refuse: Option<Status>,
    },
    /// Delivered, or the header was refused (last index 0, non-zero status).
    Done {
        last_q: bool,
        last_index: u16,
        /// Q and bytes of the header if it is the last frame acked
        /// (zero-length message or refused header).
        hdr0: Option<(bool, Vec<u8>)>,
        /// The status the header was answered with.
        hdr_status: Status,
        /// The status the last frame (index `last_index`) was answered
        /// with; repeated for its retransmissions.
        last_status: Status,
        deadline: u64,
    },
}

/// A DSOR node: sender and receiver sides.
pub struct Node {
    cfg: Config,
    /// Q of the last frame sent per (dst, chan); absent = never sent.
    last_q: HashMap<(u8, u8), bool>,
    tx: HashMap<(u8, u8), TxTransfer>,
    rx: HashMap<(u8, u8), RxState>,
    rx_bytes: usize,
    next_handle: u64,
    out: VecDeque<Frame>,
    events: VecDeque<Event>,
    /// Messages the receiving application holds (see `app_queue`).
    app_held: usize,
    /// The receiving application went away.
    app_closed: bool,
    /// New body frames received (for `close_after_frames`).
    body_frames: u64,
    /// When the first header was accepted (for `close_after_ms`).
    first_accept: Option<u64>,
    /// FD or classic, per destination node; absent = unknown.
    peers: HashMap<u8, PeerMode>,
}

impl Node {
    /// A node with no transfers.
    pub fn new(cfg: Config) -> Node {
        Node {
            cfg,
            last_q: HashMap::new(),
            tx: HashMap::new(),
            rx: HashMap::new(),
            rx_bytes: 0,
            next_handle: 0,
            out: VecDeque::new(),
            events: VecDeque::new(),
            app_held: 0,
            app_closed: false,
            body_frames: 0,
            first_accept: None,
            peers: HashMap::new(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Number of messages being sent.
    pub fn sending(&self) -> usize {
        self.tx.len()
    }

    /// Bytes of reassembly buffers in use.
    pub fn rx_bytes(&self) -> usize {
        self.rx_bytes
    }

    /// Whether the receiving application went away.
    pub fn app_closed(&self) -> bool {
        self.app_closed
    }

    /// The receiving application goes away: every partial message is
    /// refused at its next body (REFUSED) and its buffer freed; new
    /// headers and complete messages are refused too.
    pub fn close_app(&mut self) {
        if self.app_closed {
            return;
        }
        self.app_closed = true;
        for st in self.rx.values_mut() {
            if let RxState::Receiving {
                len, buf, refuse, ..
            } = st
            {
                if refuse.is_none() {
                    *refuse = Some(Status::Refused);
                    self.rx_bytes -= usize::from(*len);
                    *buf = Vec::new();
                }
            }
        }
    }

    /// Hands a complete message to the application: OK if it took it,
    /// else the status its last frame is answered with.
    fn app_take(&mut self, d: Delivery) -> Status {
        let status = if self.app_closed {
            Status::Refused
        } else if self.cfg.app_queue.is_some_and(|q| self.app_held >= q) {
            Status::NoMemory
        } else {
            Status::Ok
        };
        if status == Status::Ok {
            self.app_held += 1;
            self.events.push_back(Event::Delivered(d));
        } else {
            self.events
                .push_back(Event::NotDelivered { msg: d, status });
        }
        status
    }

    /// Next frame to transmit.
    pub fn pop_frame(&mut self) -> Option<Frame> {
        self.out.pop_front()
    }

    /// Next event.
    pub fn pop_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// Starts sending `payload` to `dst` on the lowest free channel.
    pub fn send(
        &mut self,
        now: u64,
        dst: u8,
        prio: u8,
        kind: Kind,
        payload: Vec<u8>,
    ) -> Result<u64, SendError> {
        if dst > 0x7f {
            return Err(SendError::BadNode);
        }
        let len = u16::try_from(payload.len()).map_err(|_| SendError::TooLong)?;
        let chan = (0..16u8)
            .find(|c| !self.tx.contains_key(&(dst, *c)))
            .ok_or(SendError::Busy)?;
        let q = self.last_q.get(&(dst, chan)).is_some_and(|q| !q);
        let handle = self.next_handle;
        self.next_handle += 1;
        // FD headers only on an FD interface, for more than 8 bytes, to a
        // node not known to be classic.
        let fd_offer = self.cfg.fd && len > 8 && self.peers.get(&dst) != Some(&PeerMode::Classic);
        let t = TxTransfer {
            handle,
            prio,
            header: Header { len, kind },
            fd_offer,
            b: 8,
            len,
            payload,
            index: 0,
            q,
            sent: 0,
            deadline: 0,
        };
        self.tx.insert((dst, chan), t);
        self.transmit(now, dst, chan);
        Ok(handle)
    }

    /// Transmits the current frame of the transfer on (dst, chan).
    fn transmit(&mut self, now: u64, dst: u8, chan: u8) {
        let b_max = self.cfg.fd_b_max;
        let t = self.tx.get_mut(&(dst, chan)).expect("transfer");
        let id = Id {
            prio: t.prio,
            dst,
            src: self.cfg.node,
            typ: if t.index == 0 {
                Type::Header
            } else {
                Type::Body
            },
            q: t.q,
            chan,
        }
        .encode();
        let frame = if t.index == 0 && t.fd_offer {
            let fh = FdHeader {
                header: t.header,
                b_max,
            };
            Frame::new_fd(id, &fh.encode())
        } else if t.index == 0 {
            let (b, dlc) = t.header.encode();
            Frame::new(id, &b[..usize::from(dlc)])
        } else {
            let start = usize::from(t.b) * usize::from(t.index - 1);
            let end = start + body_payload(t.len, t.b, t.index);
            let bytes = &t.payload[start..end];
            // Classic bodies with B = 8; FD frames (the last one padded)
            // with any other B.
            if t.b == 8 {
                Frame::new(id, bytes)
            } else {
                Frame::new_fd(id, bytes)
            }
        };
        self.out.push_back(frame);
        t.sent += 1;
        t.deadline = now + self.cfg.t_ack;
        self.last_q.insert((dst, chan), t.q);
    }

    /// Handles a received extended data frame.
    pub fn on_frame(&mut self, now: u64, f: &Frame) {
        let id = Id::decode(f.id);
        // A classic node takes any frame with FDF set as malformed.
        if id.dst != self.cfg.node || (f.fd && !self.cfg.fd) {
            return;
        }
        match id.typ {
            Type::Ack => self.on_ack(now, id, f.bytes()),
            Type::Header => self.on_header(now, id, f.bytes()),
            Type::Body => self.on_body(now, id, f.bytes()),
            Type::Reserved => {}
        }
    }

    fn finish(&mut self, dst: u8, chan: u8, result: Result<(), Fail>) {
        let t = self.tx.remove(&(dst, chan)).expect("transfer");
        let last = bodies_of(t.len, t.b);
        let last_frame_sent = t.index == last;
        self.events.push_back(Event::Sent {
            handle: t.handle,
            result,
            last_frame_sent,
        });
    }

    fn on_ack(&mut self, now: u64, id: Id, b: &[u8]) {
        let key = (id.src, id.chan);
        let b_max = self.cfg.fd_b_max;
        let Some(t) = self.tx.get_mut(&key) else {
            return;
        };
        let fd_header_out = t.index == 0 && t.fd_offer;
        // Only the ack of an FD header has DLC 4; after an FD header the
        // acks of index 0 with DLC 2 or 3 are ignored, and after the
        // classic header (or the fallback) the DLC 4 ones.
        let ack = if b.len() == 4 {
            let Some(a) = FdAck::decode(b) else { return };
            if !fd_header_out || (a.status == Status::Ok && a.b > b_max) {
                return;
            }
            Ack {
                index: 0,
                status: a.status,
            }
        } else {
            let Some(a) = Ack::decode(b) else { return };
            if a.index == 0 && fd_header_out {
                return;
            }
            a
        };
        if id.q != t.q || ack.index != t.index {
            return; // stale duplicate
        }
        if fd_header_out && ack.status == Status::Ok {
            // The receiver takes FD bodies (B may still be 8: classic ones).
            t.b = b[3];
            self.peers.insert(key.0, PeerMode::Fd);
        }
        let fail = match ack.status {
            Status::Ok => None,
            Status::Refused => Some(Fail::Refused),
            Status::NoMemory => Some(Fail::NoMemory),
            Status::TooLong => Some(Fail::TooLong),
        };
        if let Some(fail) = fail {
            self.finish(key.0, key.1, Err(fail));
        } else if t.index == bodies_of(t.len, t.b) {
            self.finish(key.0, key.1, Ok(()));
        } else {
            t.index += 1;
            t.q = !t.q;
            t.sent = 0;
            self.transmit(now, key.0, key.1);
        }
    }

    fn ack(&mut self, prio: u8, to: u8, chan: u8, q: bool, index: u16, status: Status) {
        let id = Id {
            prio,
            dst: to,
            src: self.cfg.node,
            typ: Type::Ack,
            q,
            chan,
        };
        let (b, n) = Ack { index, status }.encode();
        self.out
            .push_back(Frame::new(id.encode(), &b[..usize::from(n)]));
    }

    /// Answers a header (index 0) with `status`: the 4-byte ack with body
    /// size `b` if it was an FD header, else the classic ack.
    fn ack_header(&mut self, id: Id, status: Status, fd_hdr: bool, b: u8) {
        if !fd_hdr {
            self.ack(id.prio, id.src, id.chan, id.q, 0, status);
            return;
        }
        let aid = Id {
            prio: id.prio,
            dst: id.src,
            src: self.cfg.node,
            typ: Type::Ack,
            q: id.q,
            chan: id.chan,
        };
        let b = if status == Status::Ok { b } else { 8 };
        self.out
            .push_back(Frame::new(aid.encode(), &FdAck { status, b }.encode()));
    }

    fn drop_rx(&mut self, key: (u8, u8)) {
        // A refusing state's buffer was freed when it started refusing.
        if let Some(RxState::Receiving {
            len, refuse: None, ..
        }) = self.rx.remove(&key)
        {
            self.rx_bytes -= usize::from(len);
        }
    }

    fn on_header(&mut self, now: u64, id: Id, b: &[u8]) {
        // A header of length 12 is an FD header (a classic node ignores
        // it); 4, 6, 8 classic ones. Kept in canonical form for the
        // duplicate check.
        let (h, b_max, canon) = if b.len() == 12 {
            if !self.cfg.fd {
                return;
            }
            let Some(fh) = FdHeader::decode(b) else {
                return;
            };
            (fh.header, Some(fh.b_max), fh.encode().to_vec())
        } else {
            let Some(h) = Header::decode(b) else { return };
            (h, None, b.to_vec())
        };
        let b = &canon[..];
        let fd_hdr = b_max.is_some();
        // The body size this receiver takes: the largest FD length up to
        // both B_max values.
        let body = b_max.map_or(8, |m| {
            FD_LONG_LENS
                .into_iter()
                .filter(|&l| l <= usize::from(m.min(self.cfg.fd_b_max)))
                .max()
                .unwrap_or(8) as u8
        });
        let key = (id.src, id.chan);
        let refresh = now + self.cfg.t_reasm;
        // A retransmitted header whose ack was lost: answer it as before.
        let duplicate = match self.rx.get_mut(&key) {
            Some(RxState::Receiving {
                hdr_q,
                hdr,
                next,
                deadline,
                b: chosen,
                ..
            }) if *next == 1 && *hdr_q == id.q && hdr == b => {
                *deadline = refresh;
                Some((Status::Ok, *chosen))
            }
            Some(RxState::Done {
                last_index: 0,
                hdr0: Some((q, hdr)),
                hdr_status,
                deadline,
                ..
            }) if *q == id.q && hdr == b => {
                *deadline = refresh;
                Some((*hdr_status, 8))
            }
            _ => None,
        };
        if let Some((status, chosen)) = duplicate {
            self.ack_header(id, status, fd_hdr, chosen);
            return;
        }
        self.drop_rx(key);
        let receiving = self
            .rx
            .iter()
            .filter(|((s, _), st)| *s == id.src && matches!(st, RxState::Receiving { .. }))
            .count();
        let status = if h.len > self.cfg.max_len {
            Status::TooLong
        } else if self.cfg.refuse || self.app_closed {
            Status::Refused
        } else if h.len > 0
            && (receiving >= self.cfg.max_per_peer
                || self.rx_bytes + usize::from(h.len) > self.cfg.max_bytes_total)
        {
            Status::NoMemory
        } else {
            Status::Ok
        };
        let deadline = now + self.cfg.t_reasm;
        if status == Status::Ok && h.len > 0 && self.first_accept.is_none() {
            self.first_accept = Some(now);
        }
        if status != Status::Ok || h.len == 0 {
            // A zero-length message is complete with its header: the
            // header's ack says whether the application took it.
            let status = if status == Status::Ok {
                self.app_take(Delivery {
                    src: id.src,
                    prio: id.prio,
                    chan: id.chan,
                    kind: h.kind,
                    payload: Vec::new(),
                })
            } else {
                status
            };
            self.ack_header(id, status, fd_hdr, body);
            // Remember the answer so that a retransmission of this header
            // gets the same one (a refused message is never delivered).
            self.rx.insert(
                key,
                RxState::Done {
                    last_q: id.q,
                    last_index: 0,
                    hdr0: Some((id.q, b.to_vec())),
                    hdr_status: status,
                    last_status: status,
                    deadline,
                },
            );
            return;
        }
        self.ack_header(id, status, fd_hdr, body);
        self.rx_bytes += usize::from(h.len);
        self.rx.insert(
            key,
            RxState::Receiving {
                prio: id.prio,
                hdr_q: id.q,
                hdr: b.to_vec(),
                b: body,
                kind: h.kind,
                len: h.len,
                buf: Vec::with_capacity(usize::from(h.len)),
                next: 1,
                expect_q: !id.q,
                deadline,
                refuse: None,
            },
        );
    }

    /// Body `k` of the message `id` belongs to ended the transfer with
    /// `status` (the last body, or a refused one): remember the answer
    /// until `deadline`, for a sender that missed it, and send it.
    fn last_body_answered(&mut self, id: Id, k: u16, status: Status, deadline: u64) {
        self.rx.insert(
            (id.src, id.chan),
            RxState::Done {
                last_q: id.q,
                last_index: k,
                hdr0: None,
                hdr_status: Status::Ok,
                last_status: status,
                deadline,
            },
        );
        self.ack(id.prio, id.src, id.chan, id.q, k, status);
    }

    fn on_body(&mut self, now: u64, id: Id, b: &[u8]) {
        let key = (id.src, id.chan);
        let t_reasm = self.cfg.t_reasm;
        let reack = match self.rx.get_mut(&key) {
            None => return,
            Some(RxState::Done {
                last_q,
                last_index,
                last_status,
                ..
            }) => {
                // Only a retransmitted last body is answered, with the
                // answer it had; after a header-only transfer no body
                // belongs to it.
                if *last_q != id.q || *last_index == 0 {
                    return;
                }
                (*last_index, *last_status)
            }
            Some(RxState::Receiving {
                prio,
                kind,
                len,
                buf,
                next,
                expect_q,
                deadline,
                refuse,
                b: body,
                ..
            }) => {
                if id.q != *expect_q {
                    // The previous body again (its ack was lost); with
                    // next == 1 no body was received yet: ignore.
                    if *next == 1 {
                        return;
                    }
                    (*next - 1, Status::Ok)
                } else {
                    // The length must be the one for body size B (FDF
                    // itself is not looked at); padding is dropped.
                    if b.len() != body_frame_len(*len, *body, *next) {
                        return;
                    }
                    let b = &b[..body_payload(*len, *body, *next)];
                    let n = bodies_of(*len, *body);
                    let (prio, k, len, kind) = (*prio, *next, *len, *kind);
                    if let Some(status) = *refuse {
                        // The application went away: refuse this body,
                        // which ends the transfer.
                        self.last_body_answered(id, k, status, now + t_reasm);
                        self.events.push_back(Event::NotDelivered {
                            msg: Delivery {
                                src: id.src,
                                prio,
                                chan: id.chan,
                                kind,
                                payload: Vec::new(),
                            },
                            status,
                        });
                        return;
                    }
                    buf.extend_from_slice(b);
                    self.body_frames += 1;
                    if k == n {
                        let payload = std::mem::take(buf);
                        self.rx_bytes -= usize::from(len);
                        // Hand the message over before the last ack: the
                        // ack says whether the application took it.
                        let status = self.app_take(Delivery {
                            src: id.src,
                            prio,
                            chan: id.chan,
                            kind,
                            payload,
                        });
                        self.last_body_answered(id, k, status, now + t_reasm);
                    } else {
                        *next += 1;
                        *expect_q = !*expect_q;
                        *deadline = now + t_reasm;
                        self.ack(id.prio, id.src, id.chan, id.q, k, Status::Ok);
                    }
                    if self
                        .cfg
                        .close_after_frames
                        .is_some_and(|n| self.body_frames >= n)
                    {
                        self.close_app();
                    }
                    return;
                }
            }
        };
        self.ack(id.prio, id.src, id.chan, id.q, reack.0, reack.1);
    }

    /// Runs the timers: retransmissions, send timeouts, reassembly expiry.
    pub fn poll(&mut self, now: u64) {
        if let (Some(ms), Some(t0)) = (self.cfg.close_after_ms, self.first_accept) {
            if now >= t0 + ms {
                self.close_app();
            }
        }
        let mut due: Vec<(u8, u8)> = self
            .tx
            .iter()
            .filter(|(_, t)| t.deadline <= now)
            .map(|(k, _)| *k)
            .collect();
        due.sort_unstable();
        for (dst, chan) in due {
            let t = self.tx.get_mut(&(dst, chan)).expect("transfer");
            if t.sent > self.cfg.n_retx {
                self.finish(dst, chan, Err(Fail::Timeout));
                continue;
            }
            if t.index == 0 && t.fd_offer {
                // The FD header went unanswered: fall back to the classic
                // header (same Q; it counts as a retransmission) and send
                // the classic header to this node from now on.
                t.fd_offer = false;
                self.peers.insert(dst, PeerMode::Classic);
            }
            self.transmit(now, dst, chan);
        }
        let expired: Vec<(u8, u8)> = self
            .rx
            .iter()
            .filter(|(_, st)| match st {
                RxState::Receiving { deadline, .. } | RxState::Done { deadline, .. } => {
                    *deadline <= now
                }
            })
            .map(|(k, _)| *k)
            .collect();
        for key in expired {
            self.drop_rx(key);
        }
    }

    /// The earliest time [`Node::poll`] has something to do.
    pub fn next_deadline(&self) -> Option<u64> {
        let tx = self.tx.values().map(|t| t.deadline);
        let rx = self.rx.values().map(|st| match st {
            RxState::Receiving { deadline, .. } | RxState::Done { deadline, .. } => *deadline,
        });
        let close = match (self.cfg.close_after_ms, self.first_accept) {
            (Some(ms), Some(t0)) if !self.app_closed => Some(t0 + ms),
            _ => None,
        };
        tx.chain(rx).chain(close).min()
    }
}

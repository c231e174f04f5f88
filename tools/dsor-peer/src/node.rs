// SPDX-License-Identifier: GPL-2.0
//! One DSOR node: the stop-and-wait sender and the reassembling receiver
//! (Documentation/networking/rcan/dsor-wire.rst; thesis 5.3.3), with no I/O.
//!
//! The caller feeds received frames ([`Node::on_frame`]) and the time
//! ([`Node::poll`]), and takes out frames to transmit ([`Node::pop_frame`])
//! and events ([`Node::pop_event`]). Time is a number of milliseconds from
//! any origin, so tests run on a virtual clock.

use crate::wire::{bodies, body_dlc, Ack, Frame, Header, Id, Kind, Status, Type};
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

/// A message being sent on one (dst, channel).
struct TxTransfer {
    handle: u64,
    prio: u8,
    header: ([u8; 8], u8),
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
        hdr: Vec<u8>,
        kind: Kind,
        len: u16,
        buf: Vec<u8>,
        /// Index of the body expected next (1..=n).
        next: u16,
        expect_q: bool,
        deadline: u64,
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
        let t = TxTransfer {
            handle,
            prio,
            header: Header { len, kind }.encode(),
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
        let t = self.tx.get_mut(&(dst, chan)).expect("transfer");
        let (typ, bytes): (Type, &[u8]) = if t.index == 0 {
            (Type::Header, &t.header.0[..usize::from(t.header.1)])
        } else {
            let start = 8 * usize::from(t.index - 1);
            let end = start + usize::from(body_dlc(t.len, t.index));
            (Type::Body, &t.payload[start..end])
        };
        let id = Id {
            prio: t.prio,
            dst,
            src: self.cfg.node,
            typ,
            q: t.q,
            chan,
        };
        self.out.push_back(Frame::new(id.encode(), bytes));
        t.sent += 1;
        t.deadline = now + self.cfg.t_ack;
        self.last_q.insert((dst, chan), t.q);
    }

    /// Handles a received extended data frame.
    pub fn on_frame(&mut self, now: u64, f: &Frame) {
        let id = Id::decode(f.id);
        if id.dst != self.cfg.node {
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
        let last = bodies(t.len);
        let last_frame_sent = t.index == last;
        self.events.push_back(Event::Sent {
            handle: t.handle,
            result,
            last_frame_sent,
        });
    }

    fn on_ack(&mut self, now: u64, id: Id, b: &[u8]) {
        let Some(ack) = Ack::decode(b) else { return };
        let key = (id.src, id.chan);
        let Some(t) = self.tx.get_mut(&key) else {
            return;
        };
        if id.q != t.q || ack.index != t.index {
            return; // stale duplicate
        }
        let fail = match ack.status {
            Status::Ok => None,
            Status::Refused => Some(Fail::Refused),
            Status::NoMemory => Some(Fail::NoMemory),
            Status::TooLong => Some(Fail::TooLong),
        };
        if let Some(fail) = fail {
            self.finish(key.0, key.1, Err(fail));
        } else if t.index == bodies(t.len) {
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

    fn drop_rx(&mut self, key: (u8, u8)) {
        if let Some(RxState::Receiving { len, .. }) = self.rx.remove(&key) {
            self.rx_bytes -= usize::from(len);
        }
    }

    fn on_header(&mut self, now: u64, id: Id, b: &[u8]) {
        let Some(h) = Header::decode(b) else { return };
        let key = (id.src, id.chan);
        let refresh = now + self.cfg.t_reasm;
        // A retransmitted header whose ack was lost: answer it as before.
        let duplicate = match self.rx.get_mut(&key) {
            Some(RxState::Receiving {
                hdr_q,
                hdr,
                next,
                deadline,
                ..
            }) if *next == 1 && *hdr_q == id.q && hdr == b => {
                *deadline = refresh;
                Some(Status::Ok)
            }
            Some(RxState::Done {
                last_index: 0,
                hdr0: Some((q, hdr)),
                hdr_status,
                deadline,
                ..
            }) if *q == id.q && hdr == b => {
                *deadline = refresh;
                Some(*hdr_status)
            }
            _ => None,
        };
        if let Some(status) = duplicate {
            self.ack(id.prio, id.src, id.chan, id.q, 0, status);
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
        } else if self.cfg.refuse {
            Status::Refused
        } else if h.len > 0
            && (receiving >= self.cfg.max_per_peer
                || self.rx_bytes + usize::from(h.len) > self.cfg.max_bytes_total)
        {
            Status::NoMemory
        } else {
            Status::Ok
        };
        self.ack(id.prio, id.src, id.chan, id.q, 0, status);
        let deadline = now + self.cfg.t_reasm;
        if status != Status::Ok || h.len == 0 {
            // Remember the answer so that a retransmission of this header
            // gets the same one (a refused message is never delivered).
            self.rx.insert(
                key,
                RxState::Done {
                    last_q: id.q,
                    last_index: 0,
                    hdr0: Some((id.q, b.to_vec())),
                    hdr_status: status,
                    deadline,
                },
            );
            if status != Status::Ok {
                return;
            }
            self.events.push_back(Event::Delivered(Delivery {
                src: id.src,
                prio: id.prio,
                chan: id.chan,
                kind: h.kind,
                payload: Vec::new(),
            }));
            return;
        }
        self.rx_bytes += usize::from(h.len);
        self.rx.insert(
            key,
            RxState::Receiving {
                prio: id.prio,
                hdr_q: id.q,
                hdr: b.to_vec(),
                kind: h.kind,
                len: h.len,
                buf: Vec::with_capacity(usize::from(h.len)),
                next: 1,
                expect_q: !id.q,
                deadline,
            },
        );
    }

    fn on_body(&mut self, now: u64, id: Id, b: &[u8]) {
        let key = (id.src, id.chan);
        let t_reasm = self.cfg.t_reasm;
        let reack = match self.rx.get_mut(&key) {
            None => return,
            Some(RxState::Done {
                last_q, last_index, ..
            }) => {
                // Only a retransmitted last body is answered; after a
                // header-only transfer no body belongs to it.
                if *last_q != id.q || *last_index == 0 {
                    return;
                }
                *last_index
            }
            Some(RxState::Receiving {
                prio,
                kind,
                len,
                buf,
                next,
                expect_q,
                deadline,
                ..
            }) => {
                if id.q != *expect_q {
                    // The previous body again (its ack was lost); with
                    // next == 1 no body was received yet: ignore.
                    if *next == 1 {
                        return;
                    }
                    *next - 1
                } else {
                    if b.len() != usize::from(body_dlc(*len, *next)) {
                        return;
                    }
                    buf.extend_from_slice(b);
                    let (prio, k, len, kind) = (*prio, *next, *len, *kind);
                    if k == bodies(len) {
                        let payload = std::mem::take(buf);
                        self.rx_bytes -= usize::from(len);
                        self.rx.insert(
                            key,
                            RxState::Done {
                                last_q: id.q,
                                last_index: k,
                                hdr0: None,
                                hdr_status: Status::Ok,
                                deadline: now + t_reasm,
                            },
                        );
                        self.ack(id.prio, id.src, id.chan, id.q, k, Status::Ok);
                        self.events.push_back(Event::Delivered(Delivery {
                            src: id.src,
                            prio,
                            chan: id.chan,
                            kind,
                            payload,
                        }));
                    } else {
                        *next += 1;
                        *expect_q = !*expect_q;
                        *deadline = now + t_reasm;
                        self.ack(id.prio, id.src, id.chan, id.q, k, Status::Ok);
                    }
                    return;
                }
            }
        };
        self.ack(id.prio, id.src, id.chan, id.q, reack, Status::Ok);
    }

    /// Runs the timers: retransmissions, send timeouts, reassembly expiry.
    pub fn poll(&mut self, now: u64) {
        let mut due: Vec<(u8, u8)> = self
            .tx
            .iter()
            .filter(|(_, t)| t.deadline <= now)
            .map(|(k, _)| *k)
            .collect();
        due.sort_unstable();
        for (dst, chan) in due {
            let t = &self.tx[&(dst, chan)];
            if t.sent > self.cfg.n_retx {
                self.finish(dst, chan, Err(Fail::Timeout));
            } else {
                self.transmit(now, dst, chan);
            }
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
        tx.chain(rx).min()
    }
}

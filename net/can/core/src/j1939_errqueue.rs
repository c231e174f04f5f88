// SPDX-License-Identifier: GPL-2.0
//! The error queue notifications of a CAN_J1939 socket (mainline's
//! `j1939_sk_errqueue` in `net/can/j1939/socket.c`, rewritten): which
//! transport events a socket is told of, under which `SO_TIMESTAMPING`
//! flags, and what each carries: a `struct sock_extended_err`'s errno,
//! origin, info and data, and netlink attributes of statistics
//! (`J1939_NLA_*`, read by user space as `SCM_TIMESTAMPING_OPT_STATS`).
//!
//! A sender's socket (with `SO_J1939_ERRQUEUE` on) is told when the
//! receiver acknowledged the whole message (`TxAck`, under
//! `SOF_TIMESTAMPING_TX_ACK`), when a CTS acknowledged part of it
//! (`TxSched`, under `SOF_TIMESTAMPING_TX_SCHED`), and always when the
//! session was aborted (`TxAbort`, `J1939_EE_INFO_TX_ABORT`); the sockets
//! that would receive a message (with the queue on and
//! `SOF_TIMESTAMPING_RX_SOFTWARE`) are told when its session starts
//! (`RxRts`, with the message's size, PGN, NAMEs and addresses), at each
//! ETP DPO (`RxDpo`) and when it is aborted (`RxAbort`). With
//! `SOF_TIMESTAMPING_OPT_ID` the data is the send's timestamp key.

use super::j1939::{
    J1939_EE_INFO_RX_ABORT, J1939_EE_INFO_RX_DPO, J1939_EE_INFO_RX_RTS, J1939_EE_INFO_TX_ABORT,
    J1939_NLA_BYTES_ACKED, J1939_NLA_DEST_ADDR, J1939_NLA_DEST_NAME, J1939_NLA_PGN,
    J1939_NLA_SRC_ADDR, J1939_NLA_SRC_NAME, J1939_NLA_TOTAL_SIZE,
};

/// `ENOMSG`: the errno of notifications that are not errors.
pub const ENOMSG: u32 = 42;
/// `SO_EE_ORIGIN_LOCAL`.
pub const SO_EE_ORIGIN_LOCAL: u8 = 1;
/// `SO_EE_ORIGIN_TIMESTAMPING`.
pub const SO_EE_ORIGIN_TIMESTAMPING: u8 = 4;
/// `SCM_TSTAMP_SCHED`.
pub const SCM_TSTAMP_SCHED: u32 = 1;
/// `SCM_TSTAMP_ACK`.
pub const SCM_TSTAMP_ACK: u32 = 2;
/// `SOF_TIMESTAMPING_RX_SOFTWARE`.
pub const SOF_TIMESTAMPING_RX_SOFTWARE: u32 = 1 << 3;
/// `SOF_TIMESTAMPING_OPT_ID`.
pub const SOF_TIMESTAMPING_OPT_ID: u32 = 1 << 7;
/// `SOF_TIMESTAMPING_TX_SCHED`.
pub const SOF_TIMESTAMPING_TX_SCHED: u32 = 1 << 8;
/// `SOF_TIMESTAMPING_TX_ACK`.
pub const SOF_TIMESTAMPING_TX_ACK: u32 = 1 << 9;

/// An event of a transport session a socket may be told of.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Event {
    /// The sender's message was acknowledged whole.
    TxAck,
    /// A CTS acknowledged part of the sender's message.
    TxSched,
    /// The sender's session was aborted with this errno.
    TxAbort(i32),
    /// A receive session started.
    RxRts,
    /// An ETP receive session got a DPO.
    RxDpo,
    /// A receive session was aborted with this errno.
    RxAbort(i32),
}

/// What a notification says of its session.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Session {
    /// The message's size.
    pub size: u32,
    /// Bytes the receiver acknowledged so far (a sender's; 0 for a
    /// receiver, as mainline).
    pub acked: u32,
    /// The message's PGN.
    pub pgn: u32,
    /// Source and destination NAMEs (0: none) and addresses.
    pub src_name: u64,
    /// See `src_name`.
    pub dst_name: u64,
    /// The originator's address.
    pub sa: u8,
    /// The responder's address (0xFF: broadcast).
    pub da: u8,
    /// The sender's timestamp key (`SOF_TIMESTAMPING_OPT_ID`).
    pub tskey: u32,
}

/// The largest statistics a notification carries (those of `RxRts`).
pub const STATS_MAX: usize = 56;

/// A notification: the `sock_extended_err` fields and the statistics.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Note {
    /// `ee_errno` (positive).
    pub errno: u32,
    /// `ee_origin`.
    pub origin: u8,
    /// `ee_info`.
    pub info: u32,
    /// `ee_data`: the timestamp key with `SOF_TIMESTAMPING_OPT_ID`, else 0.
    pub data: u32,
    stats: [u8; STATS_MAX],
    len: usize,
}

impl Note {
    /// The netlink attributes of the statistics.
    pub fn stats(&self) -> &[u8] {
        &self.stats[..self.len]
    }

    /// Appends attribute `ty` with `payload` (`struct nlattr`: length and
    /// type, 16 bits each in host order, the payload padded to 4 bytes;
    /// a 64-bit value gets no pad attribute, as on architectures with
    /// efficient unaligned access, x86 among them).
    fn put(&mut self, ty: i32, payload: &[u8]) {
        let n = 4 + payload.len();
        let total = n.div_ceil(4) * 4;
        let Some(dst) = self.stats.get_mut(self.len..self.len + total) else {
            return;
        };
        dst[..2].copy_from_slice(&(n as u16).to_ne_bytes());
        dst[2..4].copy_from_slice(&(ty as u16).to_ne_bytes());
        dst[4..n].copy_from_slice(payload);
        dst[n..].fill(0);
        self.len += total;
    }
}

/// The notification of `ev` for a socket whose `sk_tsflags` are
/// `tsflags` (its `SO_J1939_ERRQUEUE` is on: the caller checks), or
/// `None` when its flags do not ask for it.
pub fn note(ev: Event, tsflags: u32, s: &Session) -> Option<Note> {
    let wanted = match ev {
        Event::TxAck => tsflags & SOF_TIMESTAMPING_TX_ACK != 0,
        Event::TxSched => tsflags & SOF_TIMESTAMPING_TX_SCHED != 0,
        Event::TxAbort(_) => true,
        Event::RxRts | Event::RxDpo | Event::RxAbort(_) => {
            tsflags & SOF_TIMESTAMPING_RX_SOFTWARE != 0
        }
    };
    if !wanted {
        return None;
    }
    let (errno, origin, info) = match ev {
        Event::TxAck => (ENOMSG, SO_EE_ORIGIN_TIMESTAMPING, SCM_TSTAMP_ACK),
        Event::TxSched => (ENOMSG, SO_EE_ORIGIN_TIMESTAMPING, SCM_TSTAMP_SCHED),
        Event::TxAbort(e) => (e as u32, SO_EE_ORIGIN_LOCAL, J1939_EE_INFO_TX_ABORT as u32),
        Event::RxRts => (ENOMSG, SO_EE_ORIGIN_LOCAL, J1939_EE_INFO_RX_RTS as u32),
        Event::RxDpo => (ENOMSG, SO_EE_ORIGIN_LOCAL, J1939_EE_INFO_RX_DPO as u32),
        Event::RxAbort(e) => (e as u32, SO_EE_ORIGIN_LOCAL, J1939_EE_INFO_RX_ABORT as u32),
    };
    let mut n = Note {
        errno,
        origin,
        info,
        data: if tsflags & SOF_TIMESTAMPING_OPT_ID != 0 {
            s.tskey
        } else {
            0
        },
        stats: [0; STATS_MAX],
        len: 0,
    };
    if ev == Event::RxRts {
        n.put(J1939_NLA_TOTAL_SIZE, &s.size.to_ne_bytes());
        n.put(J1939_NLA_PGN, &s.pgn.to_ne_bytes());
        n.put(J1939_NLA_SRC_NAME, &s.src_name.to_ne_bytes());
        n.put(J1939_NLA_DEST_NAME, &s.dst_name.to_ne_bytes());
        n.put(J1939_NLA_SRC_ADDR, &[s.sa]);
        n.put(J1939_NLA_DEST_ADDR, &[s.da]);
    } else {
        n.put(J1939_NLA_BYTES_ACKED, &s.acked.min(s.size).to_ne_bytes());
    }
    Some(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Session = Session {
        size: 100,
        acked: 70,
        pgn: 0x12300,
        src_name: 0x1122_3344_5566_7788,
        dst_name: 0,
        sa: 0x20,
        da: 0x30,
        tskey: 5,
    };

    /// Walks netlink attributes: (type, payload) pairs.
    fn attrs(b: &[u8]) -> Vec<(u16, Vec<u8>)> {
        let mut out = vec![];
        let mut i = 0;
        while i + 4 <= b.len() {
            let len = u16::from_ne_bytes([b[i], b[i + 1]]) as usize;
            let ty = u16::from_ne_bytes([b[i + 2], b[i + 3]]);
            out.push((ty, b[i + 4..i + len].to_vec()));
            i += len.div_ceil(4) * 4;
        }
        assert_eq!(i, b.len());
        out
    }

    #[test]
    fn flags_choose_the_notifications() {
        let all = SOF_TIMESTAMPING_TX_ACK | SOF_TIMESTAMPING_TX_SCHED | SOF_TIMESTAMPING_RX_SOFTWARE;
        for ev in [
            Event::TxAck,
            Event::TxSched,
            Event::TxAbort(113),
            Event::RxRts,
            Event::RxDpo,
            Event::RxAbort(62),
        ] {
            assert!(note(ev, all, &S).is_some(), "{ev:?}");
        }
        assert_eq!(note(Event::TxAck, SOF_TIMESTAMPING_TX_SCHED, &S), None);
        assert_eq!(note(Event::TxSched, SOF_TIMESTAMPING_TX_ACK, &S), None);
        assert_eq!(note(Event::RxRts, SOF_TIMESTAMPING_TX_ACK, &S), None);
        assert_eq!(note(Event::RxAbort(62), 0, &S), None);
        // An aborted send is told whatever the flags.
        assert!(note(Event::TxAbort(113), 0, &S).is_some());
    }

    #[test]
    fn what_each_carries() {
        let ack = note(Event::TxAck, SOF_TIMESTAMPING_TX_ACK, &S).unwrap();
        assert_eq!(
            (ack.errno, ack.origin, ack.info, ack.data),
            (ENOMSG, SO_EE_ORIGIN_TIMESTAMPING, SCM_TSTAMP_ACK, 0)
        );
        assert_eq!(attrs(ack.stats()), vec![(1, 70u32.to_ne_bytes().to_vec())]);
        let ab = note(
            Event::TxAbort(113),
            SOF_TIMESTAMPING_OPT_ID,
            &Session { acked: 900, ..S },
        )
        .unwrap();
        assert_eq!((ab.errno, ab.origin, ab.info, ab.data), (113, 1, 1, 5));
        // Never more than the message.
        assert_eq!(attrs(ab.stats()), vec![(1, 100u32.to_ne_bytes().to_vec())]);
        let rts = note(Event::RxRts, SOF_TIMESTAMPING_RX_SOFTWARE, &S).unwrap();
        assert_eq!((rts.errno, rts.origin, rts.info), (ENOMSG, 1, 2));
        assert_eq!(rts.stats().len(), STATS_MAX);
        assert_eq!(
            attrs(rts.stats()),
            vec![
                (2, 100u32.to_ne_bytes().to_vec()),
                (3, 0x12300u32.to_ne_bytes().to_vec()),
                (4, S.src_name.to_ne_bytes().to_vec()),
                (5, 0u64.to_ne_bytes().to_vec()),
                (6, vec![0x20]),
                (7, vec![0x30]),
            ]
        );
        let dpo = note(Event::RxDpo, SOF_TIMESTAMPING_RX_SOFTWARE, &S).unwrap();
        assert_eq!(dpo.info, 3);
        let rab = note(Event::RxAbort(62), SOF_TIMESTAMPING_RX_SOFTWARE, &S).unwrap();
        assert_eq!((rab.errno, rab.info), (62, 4));
    }
}

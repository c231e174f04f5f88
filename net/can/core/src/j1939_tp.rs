// SPDX-License-Identifier: GPL-2.0
//! The J1939 transport protocols (SAE J1939-21 5.10 and 5.10.5): TP
//! (RTS/CTS, up to 1,785 bytes), its broadcast form BAM, and ETP (up to
//! 117,440,505 bytes, with DPO), as pure state machines over virtual
//! time: mainline's `net/can/j1939/transport.c`, rewritten.
//!
//! This file has what both directions share (commands, timeouts, abort
//! reasons, the step a machine returns, routing, the session table);
//! the machines are [`super::j1939_tp_tx::TxSession`], one per message a
//! socket sends with more than 8 bytes, and
//! [`super::j1939_tp_rx::RxSession`], one per message a local address (or,
//! for BAM, anyone) receives. [`Sessions`] keeps mainline's rule of one active
//! session per source, destination, type (TP/ETP) and direction: a second
//! gets `EAGAIN`. The caller owns the message: the sender's data buffer
//! is passed to every sender event, the receiver's reassembly buffer to
//! every receiver event (its length is checked against the announced
//! size, so no event ever writes outside it). Each event returns a
//! [`Step`]: at most one frame to send now, what to do with the
//! session's one timer (absolute deadlines in ns; an early expiry is
//! ignored), and whether the session ended, how, and what to tell the
//! error queue. A burst of data packets comes one frame per step, the
//! next with the timer armed at "now" (or `now` plus the packet delay):
//! the caller calls the sender's `on_timer` again at once. The caller
//! serializes all calls on one session (the module: the session lock,
//! softirq context for frames and timers, process context for the start
//! of a send).
//!
//! Timeouts (J1939-21 5.10.2.4; mainline's values where they differ):
//!
//! | name | value | who waits for what |
//! |---|---|---|
//! | T1 | 750 ms | receiver, for the next data packet (also after DPO and BAM) |
//! | T2 | 1250 ms | receiver, for data after sending a CTS |
//! | T3 | 1250 ms | sender, for CTS or EOMA after RTS or a window's last packet |
//! | T4 | 550 ms (mainline; standard 1050 ms) | sender, after a hold (CTS with 0 packets) |
//! | Th | 500 ms | a receiver's hold repetition: ours never holds (as mainline) |
//! | Tr | 200 ms | response time: ours responds at once (as mainline) |
//! | echo | 250 ms | sender, for the echo of its last sent data packet (mainline) |
//! | BAM gap | 50 ms | between BAM and data packets (mainline; standard 50..200) |
//!
//! Where we chose the standard over mainline, or simplified, see
//! Documentation/networking/rcan/j1939.rst, "Mainline or the standard"; each
//! place is also marked "(mainline: ...)" below.

use super::arb::EINVAL;
use super::j1939::{
    Frame, Id, EADDRNOTAVAIL, EAGAIN, EALREADY, EBADMSG, EDESTADDRREQ, EHOSTUNREACH, EILSEQ,
    EMSGSIZE, ENETUNREACH, ENOTCONN, ENOTRECOVERABLE, EPROTO, J1939_NO_ADDR, MAX_ETP_SIZE,
    MAX_TP_SIZE, MIN_TP_SIZE,
};

/// PGN of TP connection management (TP.CM).
pub const TP_PGN_CTL: u32 = 0xec00;
/// PGN of TP data transfer (TP.DT).
pub const TP_PGN_DAT: u32 = 0xeb00;
/// PGN of ETP connection management (ETP.CM).
pub const ETP_PGN_CTL: u32 = 0xc800;
/// PGN of ETP data transfer (ETP.DT).
pub const ETP_PGN_DAT: u32 = 0xc700;

/// TP.CM_RTS.
pub const TP_CMD_RTS: u8 = 0x10;
/// TP.CM_CTS.
pub const TP_CMD_CTS: u8 = 0x11;
/// TP.CM_EndOfMsgAck.
pub const TP_CMD_EOMA: u8 = 0x13;
/// TP.CM_BAM.
pub const TP_CMD_BAM: u8 = 0x20;
/// ETP.CM_RTS.
pub const ETP_CMD_RTS: u8 = 0x14;
/// ETP.CM_CTS.
pub const ETP_CMD_CTS: u8 = 0x15;
/// ETP.CM_DPO.
pub const ETP_CMD_DPO: u8 = 0x16;
/// ETP.CM_EOMA.
pub const ETP_CMD_EOMA: u8 = 0x17;
/// TP.Conn_Abort and ETP.Conn_Abort.
pub const CMD_ABORT: u8 = 0xff;

const MS: u64 = 1_000_000;
/// T1 (ns).
pub const T1_NS: u64 = 750 * MS;
/// T2 (ns).
pub const T2_NS: u64 = 1250 * MS;
/// T3 (ns).
pub const T3_NS: u64 = 1250 * MS;
/// T4 as mainline uses it: the wait after a hold (ns).
pub const T4_NS: u64 = 550 * MS;
/// The sender's wait for the echo of its last data packet (ns).
pub const ECHO_NS: u64 = 250 * MS;
/// The gap before each BAM data packet (ns).
pub const BAM_GAP_NS: u64 = 50 * MS;
/// Consecutive refusals of the device (full queue) before a session
/// gives up with `ENETUNREACH` (mainline's `J1939_XTP_TX_RETRY_LIMIT`).
pub const RETRY_LIMIT: u32 = 100;
/// The base of the retry delay; the caller adds 0..=15 ms of jitter.
pub const RETRY_NS: u64 = 10 * MS;

/// Connection abort reasons (J1939-21 table 7; mainline's codes).
pub mod abort {
    /// Already in one or more sessions and cannot support another.
    pub const BUSY: u8 = 1;
    /// System resources were needed for another task.
    pub const RESOURCE: u8 = 2;
    /// A timeout occurred.
    pub const TIMEOUT: u8 = 3;
    /// CTS received while a data transfer is in progress.
    pub const GENERIC: u8 = 4;
    /// Maximum retransmit request limit reached (mainline: any fault).
    pub const FAULT: u8 = 5;
    /// Unexpected data transfer packet.
    pub const UNEXPECTED_DATA: u8 = 6;
    /// Bad sequence number.
    pub const BAD_SEQ: u8 = 7;
    /// Duplicate sequence number.
    pub const DUP_SEQ: u8 = 8;
    /// Unexpected EDPO packet (ETP), or message size over 1785 (TP).
    pub const EDPO_UNEXPECTED: u8 = 9;
    /// Unexpected EDPO PGN.
    pub const BAD_EDPO_PGN: u8 = 10;
    /// EDPO number of packets greater than CTS.
    pub const EDPO_OUTOF_CTS: u8 = 11;
    /// Bad EDPO offset.
    pub const BAD_EDPO_OFFSET: u8 = 12;
    /// Deprecated "any other reason".
    pub const OTHER_DEPRECATED: u8 = 13;
    /// Unexpected ECTS PGN.
    pub const ECTS_UNXPECTED_PGN: u8 = 14;
    /// ECTS requested packets exceed the message size.
    pub const ECTS_TOO_BIG: u8 = 15;
    /// Any other reason.
    pub const OTHER: u8 = 250;
}

/// The errno a socket sees for abort reason `code` (mainline's
/// `j1939_xtp_abort_to_errno`; unknown codes give `EPROTO`).
pub const fn abort_errno(code: u8) -> i32 {
    match code {
        abort::BUSY => EALREADY,
        abort::RESOURCE => EMSGSIZE,
        abort::TIMEOUT => EHOSTUNREACH,
        abort::GENERIC => EBADMSG,
        abort::FAULT => ENOTRECOVERABLE,
        abort::UNEXPECTED_DATA => ENOTCONN,
        abort::BAD_SEQ => EILSEQ,
        _ => EPROTO,
    }
}

/// What to do with a session's one timer after an event.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum TimerCmd {
    /// Leave it as it is.
    Keep,
    /// (Re)arm it to expire at this time (possibly now: call again).
    Arm(u64),
    /// Cancel it.
    Cancel,
}

/// The transport of a session.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Kind {
    /// TP with RTS/CTS (9..=1785 bytes, one destination).
    Tp,
    /// TP broadcast (BAM, 9..=1785 bytes, destination 0xFF).
    Bam,
    /// ETP (1786..=117,440,505 bytes, one destination).
    Etp,
}

impl Kind {
    pub(super) fn ctl_pgn(self) -> u32 {
        if self == Kind::Etp {
            ETP_PGN_CTL
        } else {
            TP_PGN_CTL
        }
    }

    pub(super) fn dat_pgn(self) -> u32 {
        if self == Kind::Etp {
            ETP_PGN_DAT
        } else {
            TP_PGN_DAT
        }
    }
}

/// How a session ended.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Outcome {
    /// Sender: the receiver acknowledged the message (EOMA), or for
    /// BAM the last packet's echo came back (mainline's TX ACK).
    Sent,
    /// Receiver: the reassembly buffer holds the whole message of this
    /// many bytes; deliver it.
    Delivered(usize),
    /// The session was aborted: `errno` for the socket (the error queue's
    /// `ee_errno`), `reason` the abort code sent or received, if any.
    Aborted {
        /// The socket's errno.
        errno: i32,
        /// The abort code on the wire, if one was sent or received.
        reason: Option<u8>,
    },
}

/// An error queue notification ([`super::j1939::J1939_EE_INFO_RX_RTS`]
/// and the others) that an event raised besides its outcome.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Notify {
    /// A receive session started (RTS or BAM accepted).
    RxRts,
    /// An ETP receive session got a DPO.
    RxDpo,
    /// The sender got a CTS after data: this many bytes acknowledged
    /// (mainline's `SCM_TSTAMP_SCHED`).
    TxSched(u32),
}

/// What the caller does after an event.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Step {
    /// A frame to send now.
    pub frame: Option<Frame>,
    /// The session's timer.
    pub timer: TimerCmd,
    /// The session ended (the caller releases its [`Sessions`] slot).
    pub done: Option<Outcome>,
    /// An error queue notification.
    pub notify: Option<Notify>,
}

impl Step {
    /// Nothing to do.
    pub const NONE: Step = Step {
        frame: None,
        timer: TimerCmd::Keep,
        done: None,
        notify: None,
    };
}

/// The module parameters mainline has (`j1939_tp_block`,
/// `j1939_tp_packet_delay`, `tp_max_packet_size`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Params {
    /// Most packets one CTS of ours asks for (1..=255).
    pub block: u8,
    /// Gap between a unicast sender's data packets (ns; 0: back to back).
    pub packet_delay_ns: u64,
    /// Largest message accepted for reception.
    pub max_size: usize,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            block: 255,
            packet_delay_ns: 0,
            max_size: MAX_ETP_SIZE,
        }
    }
}

/// The kind of message of `size` bytes to `da` (`EINVAL` for 8 bytes
/// or fewer, which go as one frame; `EMSGSIZE` over the ETP limit;
/// `EDESTADDRREQ` for ETP to broadcast, as mainline's `j1939_tp_send`).
pub fn kind_for(size: usize, da: u8) -> Result<Kind, i32> {
    if size < MIN_TP_SIZE {
        Err(EINVAL)
    } else if size > MAX_ETP_SIZE {
        Err(EMSGSIZE)
    } else if size > MAX_TP_SIZE {
        if da == J1939_NO_ADDR {
            Err(EDESTADDRREQ)
        } else {
            Ok(Kind::Etp)
        }
    } else if da == J1939_NO_ADDR {
        Ok(Kind::Bam)
    } else {
        Ok(Kind::Tp)
    }
}

/// Packets of 7 bytes a message of `size` bytes needs.
pub const fn packets(size: usize) -> u32 {
    size.div_ceil(7) as u32
}

pub(super) fn le24(b: &[u8]) -> u32 {
    u32::from(b[0]) | u32::from(b[1]) << 8 | u32::from(b[2]) << 16
}

/// The PGN a control frame carries in bytes 5..8 (PS cut for PDU1, as
/// mainline's `j1939_xtp_ctl_to_pgn`).
pub fn ctl_pgn(d: &[u8; 8]) -> u32 {
    let pgn = le24(&d[5..8]);
    if super::j1939::pgn_is_pdu1(pgn) {
        pgn & 0xff_ff00
    } else {
        pgn
    }
}

pub(super) fn ctl(id: Id, head: [u8; 5], pgn: u32) -> Frame {
    let p = pgn.to_le_bytes();
    Frame::new(
        id,
        &[
            head[0], head[1], head[2], head[3], head[4], p[0], p[1], p[2],
        ],
    )
}

/// An abort frame from `from` to `to` for `pgn` (`prio` of the session).
pub fn abort_frame(kind_etp: bool, prio: u8, from: u8, to: u8, code: u8, pgn: u32) -> Frame {
    let id = Id {
        prio,
        pgn: if kind_etp { ETP_PGN_CTL } else { TP_PGN_CTL },
        sa: from,
        da: to,
    };
    ctl(id, [CMD_ABORT, code, 0xff, 0xff, 0xff], pgn)
}

/// What a frame on a TP/ETP PGN is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Msg {
    /// A control frame (8 bytes) with its command and the PGN it carries.
    Ctl {
        /// ETP.CM (else TP.CM).
        etp: bool,
        /// The command byte.
        cmd: u8,
        /// The PGN of bytes 5..8.
        pgn: u32,
        /// The data.
        data: [u8; 8],
    },
    /// A data packet.
    Dat {
        /// ETP.DT (else TP.DT).
        etp: bool,
    },
}

/// Classifies a received frame: `None` when it is not a transport frame,
/// or a control frame shorter than 8 bytes (mainline ignores those).
pub fn classify(id: &Id, data: &[u8]) -> Option<Msg> {
    match id.pgn {
        TP_PGN_DAT => Some(Msg::Dat { etp: false }),
        ETP_PGN_DAT => Some(Msg::Dat { etp: true }),
        TP_PGN_CTL | ETP_PGN_CTL => {
            let d: [u8; 8] = data.get(..8)?.try_into().ok()?;
            Some(Msg::Ctl {
                etp: id.pgn == ETP_PGN_CTL,
                cmd: d[0],
                pgn: ctl_pgn(&d),
                data: d,
            })
        }
        _ => None,
    }
}

/// Whether a control command travels from the originator to the
/// responder (RTS, BAM, DPO; data packets too) rather than back (CTS,
/// EOMA). Aborts go both ways.
pub const fn from_originator(cmd: u8) -> bool {
    matches!(cmd, TP_CMD_RTS | TP_CMD_BAM | ETP_CMD_RTS | ETP_CMD_DPO)
}

/// The abort a session answers a control frame with when the frame
/// names another PGN than the session's (mainline's
/// `j1939_xtp_rx_cmd_bad_pgn`): the frame is otherwise ignored and the
/// session goes on. `None`: no abort (BAM, abort, unknown commands).
pub const fn bad_pgn_abort(cmd: u8) -> Option<u8> {
    match cmd {
        TP_CMD_RTS | ETP_CMD_RTS => Some(abort::BUSY),
        TP_CMD_CTS | ETP_CMD_CTS => Some(abort::ECTS_UNXPECTED_PGN),
        ETP_CMD_DPO => Some(abort::BAD_EDPO_PGN),
        TP_CMD_EOMA | ETP_CMD_EOMA => Some(abort::OTHER),
        _ => None,
    }
}

/// The key of an active session: mainline allows one per key.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Key {
    /// The originator's address.
    pub sa: u8,
    /// The responder's address (0xFF for BAM).
    pub da: u8,
    /// ETP (else TP and BAM).
    pub etp: bool,
    /// A local sender's session (else a receiver's).
    pub tx: bool,
}

impl Key {
    /// The receiver's key for a frame from the originator (RTS, BAM,
    /// DPO, data, or an abort the originator sent).
    pub const fn rx_of(id: &Id, etp: bool) -> Key {
        Key {
            sa: id.sa,
            da: id.da,
            etp,
            tx: false,
        }
    }

    /// The sender's key for a frame from the responder (CTS, EOMA, or
    /// an abort the responder sent).
    pub const fn tx_of_reply(id: &Id, etp: bool) -> Key {
        Key {
            sa: id.da,
            da: id.sa,
            etp,
            tx: true,
        }
    }
}

/// The active sessions of one interface: at most `N`, one per [`Key`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Sessions<const N: usize> {
    keys: [Option<Key>; N],
}

impl<const N: usize> Default for Sessions<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Sessions<N> {
    /// No active session.
    pub const fn new() -> Self {
        Sessions { keys: [None; N] }
    }

    /// Activates a session with `key`: its slot, or `EAGAIN` when one
    /// with the same key is active (mainline's `j1939_session_activate`;
    /// its send path turns that into `EBUSY` for `sendmsg`),
    /// `EADDRNOTAVAIL` when all `N` slots are in use.
    pub fn activate(&mut self, key: Key) -> Result<usize, i32> {
        if self.find(key).is_some() {
            return Err(EAGAIN);
        }
        let i = self
            .keys
            .iter()
            .position(|k| k.is_none())
            .ok_or(EADDRNOTAVAIL)?;
        self.keys[i] = Some(key);
        Ok(i)
    }

    /// The slot of the active session with `key`.
    pub fn find(&self, key: Key) -> Option<usize> {
        self.keys.iter().position(|k| *k == Some(key))
    }

    /// Ends the session in `slot` (out of range or free: nothing).
    pub fn deactivate(&mut self, slot: usize) {
        if let Some(k) = self.keys.get_mut(slot) {
            *k = None;
        }
    }

    /// Number of active sessions.
    pub fn active(&self) -> usize {
        self.keys.iter().filter(|k| k.is_some()).count()
    }
}

/// What a session's deadline means.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Due {
    /// The next frame of the sender is due.
    Send,
    /// The peer (or the echo) is late: abort with [`abort::TIMEOUT`].
    Timeout,
    /// The device refused `resend`: try again.
    Retry,
}

/// What the two session machines ([`super::j1939_tp_tx::TxSession`],
/// [`super::j1939_tp_rx::RxSession`]) share at their end: a refused frame
/// retried or given up, and a cancel from outside. Each says whether it is
/// done, lends its clock, finishes with an outcome, and names the route of
/// its abort frame (the sender aborts from its source to its destination,
/// the receiver the other way).
pub(super) trait SessionEnd {
    fn is_done(&self) -> bool;
    fn clock_mut(&mut self) -> &mut Clock;
    fn end(&mut self, o: Outcome) -> Step;
    /// The session's kind, priority, abort frame source and destination,
    /// and PGN.
    fn abort_route(&self) -> (Kind, u8, u8, u8, u32);

    /// The device refused the frame of the last step at `now`: sent again
    /// after 10 ms plus `jitter_ms` (0..=15); after [`RETRY_LIMIT`]
    /// refusals in a row the session ends with `ENETUNREACH` and no abort
    /// frame (mainline).
    fn refused_step(&mut self, now: u64, jitter_ms: u8) -> Step {
        if self.is_done() {
            return Step::NONE;
        }
        match self.clock_mut().refused(now, jitter_ms) {
            Ok(timer) => Step {
                timer,
                ..Step::NONE
            },
            Err(()) => self.end(Outcome::Aborted {
                errno: ENETUNREACH,
                reason: None,
            }),
        }
    }

    /// Ends the session from outside with `errno`; with `code`, an abort
    /// frame with that reason goes out (not for BAM).
    fn cancel_step(&mut self, errno: i32, code: Option<u8>) -> Step {
        if self.is_done() {
            return Step::NONE;
        }
        let mut s = self.end(Outcome::Aborted {
            errno,
            reason: code,
        });
        let (kind, prio, from, to, pgn) = self.abort_route();
        if let (Some(c), true) = (code, kind != Kind::Bam) {
            s.frame = Some(abort_frame(kind == Kind::Etp, prio, from, to, c, pgn));
        }
        s
    }
}

/// Timer and retry bookkeeping shared by both machines.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) struct Clock {
    pub(super) deadline: Option<u64>,
    pub(super) due: Due,
    /// After a retry: the deadline and meaning the refused step had.
    saved: Option<(Option<u64>, Due)>,
    resend: Option<Frame>,
    last_sent: Option<Frame>,
    pub(super) retries: u32,
}

impl Clock {
    pub(super) const fn new() -> Clock {
        Clock {
            deadline: None,
            due: Due::Timeout,
            saved: None,
            resend: None,
            last_sent: None,
            retries: 0,
        }
    }

    pub(super) fn arm(&mut self, at: u64, due: Due) -> TimerCmd {
        self.deadline = Some(at);
        self.due = due;
        TimerCmd::Arm(at)
    }

    pub(super) fn cancel(&mut self) -> TimerCmd {
        self.deadline = None;
        TimerCmd::Cancel
    }

    pub(super) fn due(&self, now: u64) -> bool {
        self.deadline.is_some_and(|d| d <= now)
    }

    /// The device refused the frame of the last step: retry it later, or
    /// give up after [`RETRY_LIMIT`] refusals in a row.
    pub(super) fn refused(&mut self, now: u64, jitter_ms: u8) -> Result<TimerCmd, ()> {
        let Some(f) = self.last_sent else {
            return Ok(TimerCmd::Keep);
        };
        self.retries += 1;
        if self.retries > RETRY_LIMIT {
            return Err(());
        }
        if self.saved.is_none() {
            self.saved = Some((self.deadline, self.due));
        }
        self.resend = Some(f);
        let at = now.saturating_add(RETRY_NS + u64::from(jitter_ms & 15) * MS);
        Ok(self.arm(at, Due::Retry))
    }

    /// The timer expired at `now` for a retry: the frame to send again,
    /// the timer as the refused step had it (not before `now`).
    pub(super) fn retry(&mut self, now: u64) -> Step {
        let frame = self.resend.take();
        let (deadline, due) = self.saved.take().unwrap_or((None, Due::Timeout));
        let deadline = deadline.map(|d| d.max(now));
        self.deadline = deadline;
        self.due = due;
        self.last_sent = frame;
        Step {
            frame,
            timer: deadline.map_or(TimerCmd::Cancel, TimerCmd::Arm),
            ..Step::NONE
        }
    }

    pub(super) fn sent(&mut self, f: Frame) -> Option<Frame> {
        self.last_sent = Some(f);
        Some(f)
    }
}

#[cfg(test)]
mod tests {
    use super::super::j1939::{EDOM, ENETUNREACH};
    use super::super::j1939_tp_rx::RxSession;
    use super::super::j1939_tp_tx::TxSession;
    use super::*;

    const SA: u8 = 0x80;
    const DA: u8 = 0x20;
    const PGN: u32 = 0xEF00;

    fn msg(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 7 + 3) as u8).collect()
    }

    fn id(da: u8) -> Id {
        Id {
            prio: 6,
            pgn: PGN,
            sa: SA,
            da,
        }
    }

    fn d8(f: &Frame) -> [u8; 8] {
        f.data
    }

    /// Starts a sender and its receiver; returns both after the RTS and
    /// the first CTS.
    fn connected(p: &Params, data: &[u8], buf: usize) -> (TxSession, RxSession, Step) {
        let (tx, s) = TxSession::start(p, id(DA), data, 0).unwrap();
        let rts = s.frame.unwrap();
        let (rx, s) = RxSession::on_rts(p, rts.id, &d8(&rts), buf, 0).unwrap();
        assert_eq!(s.notify, Some(Notify::RxRts));
        (tx, rx, s)
    }

    #[test]
    fn tp_frames_are_the_standards() {
        let data = msg(20);
        let p = Params::default();
        let (mut tx, s) = TxSession::start(&p, id(DA), &data, 0).unwrap();
        let rts = s.frame.unwrap();
        assert_eq!(
            rts.id,
            Id {
                prio: 6,
                pgn: TP_PGN_CTL,
                sa: SA,
                da: DA
            }
        );
        assert_eq!(rts.data, [0x10, 20, 0, 3, 3, 0x00, 0xEF, 0x00]);
        assert_eq!(s.timer, TimerCmd::Arm(T3_NS));
        let (mut rx, s) = RxSession::on_rts(&p, rts.id, &rts.data, 20, 1000).unwrap();
        let cts = s.frame.unwrap();
        assert_eq!(
            cts.id,
            Id {
                prio: 6,
                pgn: TP_PGN_CTL,
                sa: DA,
                da: SA
            }
        );
        assert_eq!(cts.data, [0x11, 3, 1, 0xFF, 0xFF, 0x00, 0xEF, 0x00]);
        assert_eq!(s.timer, TimerCmd::Arm(1000 + T2_NS));
        let mut buf = vec![0u8; 20];
        let mut s = tx.on_ctl(&cts.data, &data, 2000);
        let mut dts = vec![];
        loop {
            let f = s.frame.unwrap();
            dts.push(f);
            if let TimerCmd::Arm(at) = s.timer {
                if at > 2000 {
                    assert_eq!(at, 2000 + ECHO_NS);
                    break;
                }
            }
            s = tx.on_timer(&data, 2000);
        }
        assert_eq!(dts.len(), 3);
        assert_eq!(dts[0].id.pgn, TP_PGN_DAT);
        assert_eq!(dts[0].data, [1, 3, 10, 17, 24, 31, 38, 45]);
        // The last packet is padded with 0xFF.
        assert_eq!(
            dts[2].data,
            [3, data[14], data[15], data[16], data[17], data[18], data[19], 0xFF]
        );
        let mut last = Step::NONE;
        for f in &dts {
            last = rx.on_dat(&f.data, &mut buf, 3000);
        }
        let eoma = last.frame.unwrap();
        assert_eq!(eoma.data, [0x13, 20, 0, 3, 0xFF, 0x00, 0xEF, 0x00]);
        assert_eq!(last.done, Some(Outcome::Delivered(20)));
        assert_eq!(buf, data);
        // The echo of the last packet starts T3; EOMA ends the sender.
        assert_eq!(tx.on_echo(&dts[1].data, 3000).timer, TimerCmd::Keep);
        assert_eq!(
            tx.on_echo(&dts[2].data, 3000).timer,
            TimerCmd::Arm(3000 + T3_NS)
        );
        let s = tx.on_ctl(&eoma.data, &data, 4000);
        assert_eq!(s.done, Some(Outcome::Sent));
        assert_eq!(s.timer, TimerCmd::Cancel);
        assert_eq!(tx.acked_bytes(), 20);
        assert!(tx.is_done() && rx.is_done());
    }

    #[test]
    fn bam_paces_and_completes_on_the_echo() {
        let data = msg(10);
        let p = Params::default();
        let (mut tx, s) = TxSession::start(&p, id(J1939_NO_ADDR), &data, 0).unwrap();
        assert_eq!(tx.kind(), Kind::Bam);
        let bam = s.frame.unwrap();
        assert_eq!(bam.id.da, 0xFF);
        assert_eq!(bam.data, [0x20, 10, 0, 2, 0xFF, 0x00, 0xEF, 0x00]);
        assert_eq!(s.timer, TimerCmd::Arm(BAM_GAP_NS));
        let (mut rx, s) = RxSession::on_rts(&p, bam.id, &bam.data, 64, 0).unwrap();
        assert_eq!(s.frame, None);
        assert_eq!(s.timer, TimerCmd::Arm(T1_NS));
        // Early: nothing.
        assert_eq!(tx.on_timer(&data, BAM_GAP_NS - 1), Step::NONE);
        let s1 = tx.on_timer(&data, BAM_GAP_NS);
        assert_eq!(s1.timer, TimerCmd::Arm(2 * BAM_GAP_NS));
        let s2 = tx.on_timer(&data, 2 * BAM_GAP_NS);
        assert_eq!(s2.timer, TimerCmd::Arm(2 * BAM_GAP_NS + ECHO_NS));
        let mut buf = [0u8; 64];
        let r = rx.on_dat(&s1.frame.unwrap().data, &mut buf, BAM_GAP_NS);
        assert_eq!(r.timer, TimerCmd::Arm(BAM_GAP_NS + T1_NS));
        let r = rx.on_dat(&s2.frame.unwrap().data, &mut buf, 2 * BAM_GAP_NS);
        assert_eq!(r.done, Some(Outcome::Delivered(10)));
        assert_eq!(r.frame, None);
        assert_eq!(&buf[..10], &data[..]);
        // Not the last packet's echo: nothing; the last: done.
        assert_eq!(
            tx.on_echo(&s1.frame.unwrap().data, 2 * BAM_GAP_NS),
            Step::NONE
        );
        let e = tx.on_echo(&s2.frame.unwrap().data, 2 * BAM_GAP_NS);
        assert_eq!(e.done, Some(Outcome::Sent));
    }

    #[test]
    fn bam_without_echo_times_out_silently() {
        let data = msg(9);
        let (mut tx, _) = TxSession::start(&Params::default(), id(0xFF), &data, 0).unwrap();
        tx.on_timer(&data, BAM_GAP_NS);
        tx.on_timer(&data, 2 * BAM_GAP_NS);
        let s = tx.on_timer(&data, 2 * BAM_GAP_NS + ECHO_NS);
        assert_eq!(s.frame, None);
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: EHOSTUNREACH,
                reason: Some(abort::TIMEOUT)
            })
        );
    }

    /// Runs sender and receiver back to back without loss; returns the
    /// frames on the wire.
    fn run(p: &Params, data: &[u8]) -> Vec<Frame> {
        let (mut tx, s) = TxSession::start(p, id(DA), data, 0).unwrap();
        let mut wire = vec![s.frame.unwrap()];
        let (mut rx, s) = RxSession::on_rts(p, wire[0].id, &wire[0].data, data.len(), 0).unwrap();
        let mut buf = vec![0u8; data.len()];
        let mut to_tx = vec![s.frame.unwrap()];
        let now = 0;
        let mut done = (false, false);
        while let Some(f) = to_tx.pop() {
            wire.push(f);
            let mut s = tx.on_ctl(&f.data, data, now);
            loop {
                if let Some(f) = s.frame {
                    wire.push(f);
                    if f.id.pgn == TP_PGN_DAT || f.id.pgn == ETP_PGN_DAT {
                        let r = rx.on_dat(&f.data, &mut buf, now);
                        if let Some(g) = r.frame {
                            to_tx.push(g);
                        }
                        done.1 |= r.done == Some(Outcome::Delivered(data.len()));
                        let e = tx.on_echo(&f.data, now);
                        assert_eq!(e.frame, None);
                    } else {
                        let r = rx.on_ctl(&f.data, now);
                        assert_eq!(r.frame, None);
                    }
                }
                done.0 |= s.done == Some(Outcome::Sent);
                match s.timer {
                    TimerCmd::Arm(at) if at <= now => s = tx.on_timer(data, now),
                    _ => break,
                }
            }
        }
        assert!(done.0 && done.1, "sent {} delivered {}", done.0, done.1);
        assert_eq!(buf, data);
        wire
    }

    #[test]
    fn etp_windows_and_dpo() {
        let data = msg(2000);
        let wire = run(&Params::default(), &data);
        let rts = &wire[0];
        assert_eq!(rts.id.pgn, ETP_PGN_CTL);
        assert_eq!(rts.data, [0x14, 0xD0, 0x07, 0, 0, 0x00, 0xEF, 0x00]);
        // CTS asks for 255 from packet 1, DPO offset 0, data seq 1..=255;
        // then CTS for 31 from 256, DPO offset 255, seq 1..=31; EOMA.
        assert_eq!(wire[1].data, [0x15, 255, 1, 0, 0, 0x00, 0xEF, 0x00]);
        assert_eq!(wire[2].data, [0x16, 255, 0, 0, 0, 0x00, 0xEF, 0x00]);
        assert_eq!(wire[3].data[0], 1);
        assert_eq!(wire[257].data[0], 255);
        assert_eq!(wire[258].data, [0x15, 31, 0, 1, 0, 0x00, 0xEF, 0x00]);
        assert_eq!(wire[259].data, [0x16, 31, 255, 0, 0, 0x00, 0xEF, 0x00]);
        assert_eq!(wire[260].data[..2], [1, data[255 * 7]]);
        assert_eq!(wire[290].data[0], 31);
        assert_eq!(wire[291].data, [0x17, 0xD0, 0x07, 0, 0, 0x00, 0xEF, 0x00]);
        assert_eq!(wire.len(), 292);
    }

    #[test]
    fn receiver_block_limit() {
        let data = msg(100);
        let p = Params {
            block: 4,
            ..Params::default()
        };
        let wire = run(&p, &data);
        let cts: Vec<_> = wire
            .iter()
            .filter(|f| f.data[0] == TP_CMD_CTS)
            .map(|f| (f.data[1], f.data[2]))
            .collect();
        assert_eq!(cts, [(4, 1), (4, 5), (4, 9), (3, 13)]);
    }

    #[test]
    fn sizes_at_the_limits() {
        for n in [9, 14, 15, 1785, 1786, 1792] {
            run(&Params::default(), &msg(n));
        }
    }

    #[test]
    fn hold_then_resume_and_hold_timeout() {
        let data = msg(30);
        let (mut tx, _, _) = connected(&Params::default(), &data, 30);
        let hold = [0x11, 0, 1, 0xFF, 0xFF, 0x00, 0xEF, 0x00];
        let s = tx.on_ctl(&hold, &data, 100);
        assert_eq!(s.frame, None);
        assert_eq!(s.timer, TimerCmd::Arm(100 + T4_NS));
        assert_eq!(s.notify, None);
        // Repeated holds extend the wait.
        let s = tx.on_ctl(&hold, &data, 500 * MS);
        assert_eq!(s.timer, TimerCmd::Arm(500 * MS + T4_NS));
        assert_eq!(tx.on_timer(&data, 500 * MS + T4_NS - 1), Step::NONE);
        // Resume.
        let s = tx.on_ctl(&[0x11, 2, 1, 0xFF, 0xFF, 0x00, 0xEF, 0x00], &data, 600 * MS);
        assert_eq!(s.frame.unwrap().data[0], 1);
        // A hold that is never lifted: timeout, abort 3.
        let (mut tx, _, _) = connected(&Params::default(), &data, 30);
        tx.on_ctl(&hold, &data, 0);
        let s = tx.on_timer(&data, T4_NS);
        let f = s.frame.unwrap();
        assert_eq!(f.data[..2], [0xFF, 3]);
        assert_eq!((f.id.sa, f.id.da), (SA, DA));
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: EHOSTUNREACH,
                reason: Some(3)
            })
        );
    }

    #[test]
    fn hold_next_packet_byte_is_not_checked() {
        // A receiver's hold with next packet 0xFF (beyond a 5-packet
        // message) or 0: both holds, not faults; CTS(5, 1) then resumes
        // from the first packet.
        let data = msg(30);
        for next in [0xFF, 0] {
            let (mut tx, _, _) = connected(&Params::default(), &data, 30);
            let s = tx.on_ctl(&[0x11, 0, next, 0xFF, 0xFF, 0x00, 0xEF, 0x00], &data, 100);
            assert_eq!((s.frame, s.done), (None, None), "hold with next {next:#x}");
            assert_eq!(s.timer, TimerCmd::Arm(100 + T4_NS));
            let s = tx.on_ctl(&[0x11, 5, 1, 0xFF, 0xFF, 0x00, 0xEF, 0x00], &data, 200);
            assert_eq!(s.frame.unwrap().data[0], 1, "after a hold with next {next:#x}");
        }
    }

    #[test]
    fn retransmit_request() {
        let data = msg(30);
        let (mut tx, _, s) = connected(&Params::default(), &data, 30);
        let cts = s.frame.unwrap();
        let mut s = tx.on_ctl(&cts.data, &data, 0);
        let mut seqs = vec![];
        while let Some(f) = s.frame {
            seqs.push(f.data[0]);
            if f.data[0] == 5 {
                tx.on_echo(&f.data, 0);
            }
            s = tx.on_timer(&data, 0);
        }
        assert_eq!(seqs, [1, 2, 3, 4, 5]);
        // A hold after data reports no progress (mainline's TX_SCHED
        // comes with windows only).
        let s = tx.on_ctl(&[0x11, 0, 3, 0xFF, 0xFF, 0x00, 0xEF, 0x00], &data, 5);
        assert_eq!((s.frame, s.notify), (None, None));
        // The receiver asks for packets 2 and 3 again.
        let mut s = tx.on_ctl(&[0x11, 2, 2, 0xFF, 0xFF, 0x00, 0xEF, 0x00], &data, 10);
        assert_eq!(s.notify, Some(Notify::TxSched(7)));
        let mut again = vec![];
        while let Some(f) = s.frame {
            again.push(f.data);
            s = tx.on_timer(&data, 10);
        }
        assert_eq!(again.len(), 2);
        assert_eq!(again[0][..3], [2, data[7], data[8]]);
        assert_eq!(again[1][0], 3);
    }

    #[test]
    fn cts_faults() {
        let data = msg(30);
        let cases: [([u8; 8], u8); 3] = [
            ([0x11, 2, 0, 0xFF, 0xFF, 0x00, 0xEF, 0x00], abort::FAULT),
            ([0x11, 6, 1, 0xFF, 0xFF, 0x00, 0xEF, 0x00], abort::FAULT),
            (
                [0x11, 1, 6, 0xFF, 0xFF, 0x00, 0xEF, 0x00],
                abort::ECTS_TOO_BIG,
            ),
        ];
        for (cts, code) in cases {
            let (mut tx, _, _) = connected(&Params::default(), &data, 30);
            let s = tx.on_ctl(&cts, &data, 0);
            assert_eq!(s.frame.unwrap().data[..2], [0xFF, code], "{cts:?}");
            assert!(tx.is_done());
        }
        // A CTS while a window is being sent (with a packet delay).
        let p = Params {
            packet_delay_ns: MS,
            ..Params::default()
        };
        let (mut tx, _, s) = connected(&p, &data, 30);
        let s = tx.on_ctl(&s.frame.unwrap().data, &data, 0);
        assert_eq!(s.timer, TimerCmd::Arm(MS));
        let s = tx.on_ctl(&[0x11, 1, 1, 0xFF, 0xFF, 0x00, 0xEF, 0x00], &data, 0);
        assert_eq!(s.frame.unwrap().data[..2], [0xFF, abort::GENERIC]);
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: EBADMSG,
                reason: Some(4)
            })
        );
    }

    #[test]
    fn another_pgn_is_answered_but_the_session_goes_on() {
        let data = msg(30);
        let (mut tx, mut rx, _) = connected(&Params::default(), &data, 30);
        let s = tx.on_ctl(&[0x11, 2, 1, 0xFF, 0xFF, 0x00, 0xEE, 0x00], &data, 0);
        let f = s.frame.unwrap();
        assert_eq!(f.data, [0xFF, 14, 0xFF, 0xFF, 0xFF, 0x00, 0xEE, 0x00]);
        assert!(!tx.is_done());
        let s = rx.on_ctl(&[0x10, 30, 0, 5, 5, 0x00, 0xEE, 0x00], 0);
        assert_eq!(s.frame.unwrap().data[..2], [0xFF, abort::BUSY]);
        assert!(!rx.is_done());
        // An abort for another PGN is ignored.
        assert_eq!(
            tx.on_ctl(&[0xFF, 3, 0xFF, 0xFF, 0xFF, 0x00, 0xEE, 0x00], &data, 0),
            Step::NONE
        );
        assert!(!tx.is_done());
    }

    #[test]
    fn second_rts_aborts_the_running_session() {
        let data = msg(30);
        let (_, mut rx, _) = connected(&Params::default(), &data, 30);
        let s = rx.on_ctl(&[0x10, 30, 0, 5, 5, 0x00, 0xEF, 0x00], 0);
        let f = s.frame.unwrap();
        assert_eq!(f.data[..2], [0xFF, abort::BUSY]);
        assert_eq!((f.id.sa, f.id.da), (DA, SA));
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: EALREADY,
                reason: Some(1)
            })
        );
    }

    #[test]
    fn received_abort_maps_to_errno() {
        let data = msg(30);
        for (code, errno) in [
            (1, EALREADY),
            (2, EMSGSIZE),
            (3, EHOSTUNREACH),
            (4, EBADMSG),
            (5, ENOTRECOVERABLE),
            (6, ENOTCONN),
            (7, EILSEQ),
            (8, EPROTO),
            (15, EPROTO),
            (250, EPROTO),
            (99, EPROTO),
        ] {
            let (mut tx, mut rx, _) = connected(&Params::default(), &data, 30);
            let a = [0xFF, code, 0xFF, 0xFF, 0xFF, 0x00, 0xEF, 0x00];
            let s = tx.on_ctl(&a, &data, 0);
            assert_eq!(
                s.done,
                Some(Outcome::Aborted {
                    errno,
                    reason: Some(code)
                })
            );
            assert_eq!(s.frame, None);
            let s = rx.on_ctl(&a, 0);
            assert_eq!(
                s.done,
                Some(Outcome::Aborted {
                    errno,
                    reason: Some(code)
                })
            );
        }
    }

    /// The addressing of control frames from SA to DA with priority
    /// `prio`: on TP.CM, on ETP.CM, and TP.CM to broadcast.
    fn ctl_ids(prio: u8) -> (Id, Id, Id) {
        let tp = Id {
            prio,
            pgn: TP_PGN_CTL,
            sa: SA,
            da: DA,
        };
        (tp, Id { pgn: ETP_PGN_CTL, ..tp }, Id { da: 0xFF, ..tp })
    }

    #[test]
    fn rts_checks() {
        let p = Params::default();
        let (tp, etp, bam) = ctl_ids(7);
        let code = |id: Id, d: [u8; 8], buf: usize| {
            let s = RxSession::on_rts(&p, id, &d, buf, 0).unwrap_err();
            s.frame.map(|f| {
                assert_eq!((f.id.sa, f.id.da, f.id.prio), (id.da, id.sa, 7));
                f.data[1]
            })
        };
        assert_eq!(
            code(tp, [0x10, 8, 0, 2, 2, 0, 0xEF, 0], 100),
            Some(abort::FAULT)
        );
        assert_eq!(
            code(tp, [0x10, 0xFA, 6, 255, 255, 0, 0xEF, 0], 9999),
            Some(abort::FAULT)
        );
        assert_eq!(
            code(tp, [0x10, 100, 0, 15, 15, 0, 0xEF, 0], 99),
            Some(abort::RESOURCE)
        );
        assert_eq!(
            code(tp, [0x10, 100, 0, 14, 14, 0, 0xEF, 0], 100),
            Some(abort::FAULT)
        );
        assert_eq!(
            code(etp, [0x14, 0xF9, 6, 0, 0, 0, 0xEF, 0], 9999),
            Some(abort::FAULT)
        );
        assert_eq!(
            code(etp, [0x14, 0, 0, 0, 1, 0, 0xEF, 0], 1000),
            Some(abort::RESOURCE)
        );
        assert_eq!(
            code(etp, [0x14, 0xFA, 0xFF, 0xFF, 0xFF, 0, 0xEF, 0], usize::MAX),
            Some(abort::FAULT)
        );
        let small = Params {
            max_size: 2000,
            ..p
        };
        assert!(
            RxSession::on_rts(&small, etp, &[0x14, 0xD1, 7, 0, 0, 0, 0xEF, 0], 9999, 0).is_err()
        );
        // BAM: no abort frames; BAM to unicast and RTS to broadcast ignored.
        assert_eq!(code(bam, [0x20, 8, 0, 2, 0xFF, 0, 0xEF, 0], 100), None);
        assert_eq!(code(tp, [0x20, 20, 0, 3, 0xFF, 0, 0xEF, 0], 100), None);
        assert_eq!(code(bam, [0x10, 20, 0, 3, 3, 0, 0xEF, 0], 100), None);
        assert_eq!(code(etp, [0x10, 20, 0, 3, 3, 0, 0xEF, 0], 100), None);
        // A good one takes the PGN of the RTS.
        let (rx, _) =
            RxSession::on_rts(&p, tp, &[0x10, 20, 0, 3, 1, 0x42, 0xFE, 0], 20, 0).unwrap();
        assert_eq!(rx.id().pgn, 0xFE42);
        assert_eq!(
            rx.key(),
            Key {
                sa: SA,
                da: DA,
                etp: false,
                tx: false
            }
        );
    }

    #[test]
    fn wanted_buffer_only_for_what_may_come() {
        let p = Params::default();
        let (tp, etp, bam) = ctl_ids(6);
        // TP: 20 bytes in 3 packets; a count that does not fit, too
        // short, too long: no buffer.
        let rts = [0x10, 20, 0, 3, 3, 0, 0xEF, 0];
        assert_eq!(RxSession::wanted_buffer(&p, tp, &rts), Some(20));
        assert_eq!(RxSession::wanted_buffer(&p, tp, &[0x10, 20, 0, 4, 3, 0, 0xEF, 0]), None);
        assert_eq!(RxSession::wanted_buffer(&p, tp, &[0x10, 8, 0, 2, 2, 0, 0xEF, 0]), None);
        assert_eq!(RxSession::wanted_buffer(&p, tp, &[0x10, 0xFA, 6, 0xFF, 0xFF, 0, 0xEF, 0]), None);
        // RTS to broadcast, BAM to one address, a CTS: nothing starts.
        assert_eq!(RxSession::wanted_buffer(&p, bam, &rts), None);
        assert_eq!(RxSession::wanted_buffer(&p, tp, &[0x20, 20, 0, 3, 0xFF, 0, 0xEF, 0]), None);
        assert_eq!(RxSession::wanted_buffer(&p, tp, &[0x11, 3, 1, 0xFF, 0xFF, 0, 0xEF, 0]), None);
        assert_eq!(
            RxSession::wanted_buffer(&p, bam, &[0x20, 20, 0, 3, 0xFF, 0, 0xEF, 0]),
            Some(20)
        );
        // ETP: over 1785 bytes, at most the largest, at most `max_size`.
        let big = |n: u32| {
            let b = n.to_le_bytes();
            [0x14, b[0], b[1], b[2], b[3], 0, 0xEF, 0]
        };
        assert_eq!(RxSession::wanted_buffer(&p, etp, &big(1786)), Some(1786));
        assert_eq!(RxSession::wanted_buffer(&p, etp, &big(1785)), None);
        assert_eq!(
            RxSession::wanted_buffer(&p, etp, &big(MAX_ETP_SIZE as u32)),
            Some(MAX_ETP_SIZE)
        );
        assert_eq!(RxSession::wanted_buffer(&p, etp, &big(MAX_ETP_SIZE as u32 + 1)), None);
        let small = Params {
            max_size: 4096,
            ..p
        };
        assert_eq!(RxSession::wanted_buffer(&small, etp, &big(4097)), None);
        assert_eq!(RxSession::wanted_buffer(&small, etp, &big(4096)), Some(4096));
        // What is refused gets its own abort code with `usize::MAX` as the
        // buffer: a fault for a size ETP does not carry, "resources" over
        // the limit (a 0-byte buffer would say "resources" for both).
        for (d, code) in [(big(1785), abort::FAULT), (big(4097), abort::RESOURCE)] {
            let s = RxSession::on_rts(&small, etp, &d, usize::MAX, 0).unwrap_err();
            assert_eq!(s.frame.unwrap().data[..2], [CMD_ABORT, code]);
        }
    }

    #[test]
    fn largest_etp_is_accepted() {
        let id = Id {
            prio: 6,
            pgn: ETP_PGN_CTL,
            sa: SA,
            da: DA,
        };
        let max = (MAX_ETP_SIZE as u32).to_le_bytes();
        let d = [0x14, max[0], max[1], max[2], max[3], 0x00, 0xEF, 0x00];
        let (rx, s) = RxSession::on_rts(&Params::default(), id, &d, usize::MAX, 0).unwrap();
        assert_eq!(rx.size(), 117_440_505);
        assert_eq!(s.frame.unwrap().data[..5], [0x15, 255, 1, 0, 0]);
        let over = ((MAX_ETP_SIZE + 1) as u32).to_le_bytes();
        let d = [0x14, over[0], over[1], over[2], over[3], 0x00, 0xEF, 0x00];
        let e = RxSession::on_rts(&Params::default(), id, &d, usize::MAX, 0).unwrap_err();
        assert_eq!(e.frame.unwrap().data[1], abort::FAULT);
    }

    #[test]
    fn receiver_timeouts() {
        let data = msg(30);
        // T2 after CTS.
        let (_, mut rx, _) = connected(&Params::default(), &data, 30);
        let s = rx.on_timer(T2_NS);
        assert_eq!(s.frame.unwrap().data[..2], [0xFF, 3]);
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: EHOSTUNREACH,
                reason: Some(3)
            })
        );
        // T1 between packets; a gap (lost packet) is not filled.
        let (mut tx, mut rx, s) = connected(&Params::default(), &data, 30);
        let mut buf = [0u8; 30];
        let d1 = tx.on_ctl(&s.frame.unwrap().data, &data, 0).frame.unwrap();
        let d2 = tx.on_timer(&data, 0).frame.unwrap();
        let d3 = tx.on_timer(&data, 0).frame.unwrap();
        assert_eq!(
            rx.on_dat(&d1.data, &mut buf, 10).timer,
            TimerCmd::Arm(10 + T1_NS)
        );
        assert_eq!(
            rx.on_dat(&d3.data, &mut buf, 20).timer,
            TimerCmd::Arm(20 + T1_NS)
        );
        assert_eq!(rx.received(), 7);
        // A duplicate is ignored too.
        rx.on_dat(&d1.data, &mut buf, 30);
        assert_eq!(rx.received(), 7);
        assert_eq!(rx.on_timer(30 + T1_NS - 1), Step::NONE);
        let s = rx.on_timer(30 + T1_NS);
        assert_eq!(s.frame.unwrap().data[1], 3);
        let _ = d2;
    }

    #[test]
    fn data_checks() {
        let data = msg(30);
        let (_, mut rx, _) = connected(&Params::default(), &data, 30);
        let mut buf = [0u8; 30];
        let s = rx.on_dat(&[1, 2, 3], &mut buf, 0);
        assert_eq!(s.frame.unwrap().data[1], abort::UNEXPECTED_DATA);
        let (_, mut rx, _) = connected(&Params::default(), &data, 30);
        let s = rx.on_dat(&[6, 0, 0, 0, 0, 0, 0, 0], &mut buf, 0);
        assert_eq!(s.frame.unwrap().data[1], abort::FAULT);
        // A buffer shorter than announced: no write outside, abort.
        let (_, mut rx, _) = connected(&Params::default(), &data, 30);
        let mut short = [0u8; 3];
        let s = rx.on_dat(&[1, 9, 9, 9, 9, 9, 9, 9], &mut short, 0);
        assert_eq!(s.frame.unwrap().data[1], abort::RESOURCE);
        assert_eq!(short, [0; 3]);
    }

    #[test]
    fn dpo_checks() {
        let data = msg(2000);
        let etp_id = |sa, da| Id {
            prio: 6,
            pgn: ETP_PGN_CTL,
            sa,
            da,
        };
        let start = || {
            let (tx, s) = TxSession::start(&Params::default(), id(DA), &data, 0).unwrap();
            let r = s.frame.unwrap();
            let (rx, _) = RxSession::on_rts(&Params::default(), r.id, &r.data, 2000, 0).unwrap();
            (tx, rx)
        };
        let _ = etp_id;
        let mut buf = vec![0u8; 2000];
        // Data before DPO.
        let (_, mut rx) = start();
        assert_eq!(
            rx.on_dat(&[1; 8], &mut buf, 0).frame.unwrap().data[1],
            abort::FAULT
        );
        // More packets than the CTS allowed.
        let (_, mut rx) = start();
        let s = rx.on_ctl(&[0x16, 255, 0, 0, 0, 0, 0xEF, 0], 0);
        assert_eq!(s.notify, Some(Notify::RxDpo));
        let s = rx.on_ctl(&[0x16, 255, 0, 0, 0, 0, 0xEF, 0], 0);
        assert_eq!(s.frame.unwrap().data[1], abort::EDPO_UNEXPECTED);
        let mut big = Params::default();
        big.block = 10;
        let (_, s) = TxSession::start(&big, id(DA), &data, 0).unwrap();
        let r = s.frame.unwrap();
        let (mut rx, s) = RxSession::on_rts(&big, r.id, &r.data, 2000, 0).unwrap();
        assert_eq!(s.frame.unwrap().data[1], 10);
        let s = rx.on_ctl(&[0x16, 11, 0, 0, 0, 0, 0xEF, 0], 0);
        assert_eq!(s.frame.unwrap().data[1], abort::EDPO_OUTOF_CTS);
        let (_, mut rx) = start();
        let s = rx.on_ctl(&[0x16, 5, 1, 0, 0, 0, 0xEF, 0], 0);
        assert_eq!(s.frame.unwrap().data[1], abort::BAD_EDPO_OFFSET);
        // DPO with another PGN.
        let (_, mut rx) = start();
        let s = rx.on_ctl(&[0x16, 5, 0, 0, 0, 0, 0xEE, 0], 0);
        assert_eq!(s.frame.unwrap().data[..2], [0xFF, abort::BAD_EDPO_PGN]);
        assert!(!rx.is_done());
    }

    #[test]
    fn send_checks() {
        let p = Params::default();
        assert_eq!(
            TxSession::start(&p, id(DA), &msg(8), 0).unwrap_err(),
            EINVAL
        );
        assert_eq!(
            TxSession::start(&p, id(0xFF), &msg(1786), 0).unwrap_err(),
            EDESTADDRREQ
        );
        let tp = Id {
            pgn: TP_PGN_DAT,
            ..id(DA)
        };
        assert_eq!(TxSession::start(&p, tp, &msg(20), 0).unwrap_err(), EDOM);
        assert_eq!(kind_for(MAX_ETP_SIZE + 1, DA), Err(EMSGSIZE));
        assert_eq!(kind_for(MAX_ETP_SIZE, DA), Ok(Kind::Etp));
        assert_eq!(kind_for(MAX_TP_SIZE, 0xFF), Ok(Kind::Bam));
        assert_eq!(packets(MAX_ETP_SIZE), 0xFF_FFFF);
    }

    #[test]
    fn sessions_one_per_key() {
        let mut t = Sessions::<4>::new();
        let k = Key {
            sa: 1,
            da: 2,
            etp: false,
            tx: true,
        };
        let a = t.activate(k).unwrap();
        assert_eq!(t.activate(k), Err(EAGAIN));
        // Another type, direction or pair is fine.
        t.activate(Key { etp: true, ..k }).unwrap();
        t.activate(Key { tx: false, ..k }).unwrap();
        t.activate(Key { da: 3, ..k }).unwrap();
        assert_eq!(t.activate(Key { da: 4, ..k }), Err(EADDRNOTAVAIL));
        t.deactivate(a);
        assert_eq!(t.find(k), None);
        t.activate(k).unwrap();
        t.deactivate(99);
        assert_eq!(t.active(), 4);
    }

    #[test]
    fn routing_keys() {
        let rts = Id {
            prio: 6,
            pgn: TP_PGN_CTL,
            sa: SA,
            da: DA,
        };
        let cts = Id {
            sa: DA,
            da: SA,
            ..rts
        };
        assert_eq!(
            Key::rx_of(&rts, false),
            Key {
                sa: SA,
                da: DA,
                etp: false,
                tx: false
            }
        );
        assert_eq!(
            Key::tx_of_reply(&cts, false),
            Key {
                sa: SA,
                da: DA,
                etp: false,
                tx: true
            }
        );
        assert!(from_originator(TP_CMD_RTS) && !from_originator(TP_CMD_CTS));
        let m = classify(&rts, &[0x10, 20, 0, 3, 3, 0x55, 0xEF, 0]).unwrap();
        assert_eq!(
            m,
            Msg::Ctl {
                etp: false,
                cmd: 0x10,
                pgn: 0xEF00,
                data: [0x10, 20, 0, 3, 3, 0x55, 0xEF, 0]
            }
        );
        assert_eq!(classify(&rts, &[0x10, 20, 0]), None);
        assert_eq!(
            classify(
                &Id {
                    pgn: ETP_PGN_DAT,
                    ..rts
                },
                &[]
            ),
            Some(Msg::Dat { etp: true })
        );
        assert_eq!(classify(&Id { pgn: 0xFEF1, ..rts }, &[0; 8]), None);
    }

    #[test]
    fn refused_frames_are_retried_then_given_up() {
        let data = msg(30);
        let (mut tx, _, s) = connected(&Params::default(), &data, 30);
        let cts = s.frame.unwrap();
        let d1 = tx.on_ctl(&cts.data, &data, 0).frame.unwrap();
        let s = tx.on_refused(0, 3);
        assert_eq!(s.timer, TimerCmd::Arm(13 * MS));
        assert_eq!(tx.on_timer(&data, 13 * MS - 1), Step::NONE);
        let s = tx.on_timer(&data, 13 * MS);
        assert_eq!(s.frame, Some(d1));
        // Back to the refused step's timer (the next packet, due at 0,
        // so now).
        assert_eq!(s.timer, TimerCmd::Arm(13 * MS));
        assert_eq!(tx.on_timer(&data, 13 * MS).frame.unwrap().data[0], 2);
        let mut now = 13 * MS;
        for _ in 0..RETRY_LIMIT - 1 {
            let s = tx.on_refused(now, 0);
            now += RETRY_NS;
            assert!(s.done.is_none());
            tx.on_timer(&data, now);
        }
        let s = tx.on_refused(now, 0);
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: ENETUNREACH,
                reason: None
            })
        );
        assert_eq!(s.frame, None);
    }

    #[test]
    fn cancel_from_outside() {
        let data = msg(30);
        let (mut tx, mut rx, _) = connected(&Params::default(), &data, 30);
        let s = tx.cancel(108, None);
        assert_eq!(s.frame, None);
        assert_eq!(
            s.done,
            Some(Outcome::Aborted {
                errno: 108,
                reason: None
            })
        );
        assert_eq!(tx.cancel(108, None), Step::NONE);
        let s = rx.cancel(108, Some(abort::OTHER));
        assert_eq!(s.frame.unwrap().data[..2], [0xFF, 250]);
        assert_eq!(rx.on_timer(u64::MAX), Step::NONE);
    }
}

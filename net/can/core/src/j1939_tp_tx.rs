// SPDX-License-Identifier: GPL-2.0
//! The J1939 transport sender (originator) of one message: TP with
//! RTS/CTS, BAM, and ETP with DPO, as a pure state machine over virtual
//! time (mainline's transmit side of `net/can/j1939/transport.c`,
//! rewritten). The shared parts, the timeouts and where we differ from
//! mainline are in [`super::j1939_tp`] and
//! Documentation/networking/rcan/j1939.rst, "Mainline or the standard".
//!
//! One [`TxSession`] exists per message of more than 8 bytes a socket
//! sends; it holds the position in the message, not the message: the
//! caller passes the same bytes to every event. The caller serializes
//! the events of a session.

use super::j1939::{Frame, Id, EDOM};
use super::j1939_tp::{
    abort, abort_errno, abort_frame, bad_pgn_abort, ctl, ctl_pgn, kind_for, le24, packets, Clock,
    Due, Key, Kind, Notify, Outcome, Params, SessionEnd, Step, BAM_GAP_NS, CMD_ABORT, ECHO_NS,
    ETP_CMD_CTS, ETP_CMD_DPO, ETP_CMD_EOMA, ETP_CMD_RTS, ETP_PGN_CTL, ETP_PGN_DAT, T3_NS, T4_NS,
    TP_CMD_BAM, TP_CMD_CTS, TP_CMD_EOMA, TP_CMD_RTS, TP_PGN_CTL, TP_PGN_DAT,
};

/// The states of a sender.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum TxSt {
    /// RTS (or the last packet of a window) is out: waiting for CTS or
    /// EOMA (T3), or for the echo of the window's last packet, or
    /// holding after CTS(0) (T4).
    WaitCts,
    /// Sending the packets `tx..last` of a window (or of a BAM).
    Sending,
    /// Ended.
    Done,
}

/// A sender's session (the originator).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct TxSession {
    kind: Kind,
    /// sa: ours; da: the responder (0xFF for BAM); pgn: the message's.
    id: Id,
    size: usize,
    total: u32,
    /// The "max packets per CTS" our RTS announced.
    block: u32,
    /// Next packet to send (0-based).
    tx: u32,
    /// End of the current window.
    last: u32,
    /// The data packet offset of the current ETP window.
    dpo: u32,
    /// Packets the receiver acknowledged.
    acked: u32,
    /// Waiting for the echo of the packet `last - 1`.
    echo_pending: bool,
    packet_delay: u64,
    st: TxSt,
    clock: Clock,
}

impl TxSession {
    /// Starts sending a message of `data.len()` bytes, addressed by `id`
    /// (PGN, priority, our address, the destination, 0xFF for BAM), at
    /// `now`: sends RTS (TP, ETP) or BAM. Errors as [`kind_for`], and
    /// `EDOM` for a transport PGN (mainline's `j1939_tp_send`).
    pub fn start(p: &Params, id: Id, data: &[u8], now: u64) -> Result<(TxSession, Step), i32> {
        if matches!(id.pgn, TP_PGN_CTL | TP_PGN_DAT | ETP_PGN_CTL | ETP_PGN_DAT) {
            return Err(EDOM);
        }
        let size = data.len();
        let kind = kind_for(size, id.da)?;
        let total = packets(size);
        let mut s = TxSession {
            kind,
            id,
            size,
            total,
            block: if kind == Kind::Etp { 255 } else { total },
            tx: 0,
            last: 0,
            dpo: 0,
            acked: 0,
            echo_pending: false,
            packet_delay: p.packet_delay_ns,
            st: TxSt::WaitCts,
            clock: Clock::new(),
        };
        let sz = (size as u32).to_le_bytes();
        let (head, timer) = match kind {
            Kind::Etp => (
                [ETP_CMD_RTS, sz[0], sz[1], sz[2], sz[3]],
                s.clock.arm(now.saturating_add(T3_NS), Due::Timeout),
            ),
            Kind::Tp => (
                [TP_CMD_RTS, sz[0], sz[1], total as u8, total as u8],
                s.clock.arm(now.saturating_add(T3_NS), Due::Timeout),
            ),
            Kind::Bam => {
                s.st = TxSt::Sending;
                s.last = total;
                (
                    [TP_CMD_BAM, sz[0], sz[1], total as u8, 0xff],
                    s.clock.arm(now.saturating_add(BAM_GAP_NS), Due::Send),
                )
            }
        };
        let f = ctl(s.ctl_id(), head, id.pgn);
        let step = Step {
            frame: s.clock.sent(f),
            timer,
            ..Step::NONE
        };
        Ok((s, step))
    }

    /// The transport.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// The session's key.
    pub fn key(&self) -> Key {
        Key {
            sa: self.id.sa,
            da: self.id.da,
            etp: self.kind == Kind::Etp,
            tx: true,
        }
    }

    /// Whether the session ended.
    pub fn is_done(&self) -> bool {
        self.st == TxSt::Done
    }

    /// The timer's deadline, if armed.
    pub fn deadline(&self) -> Option<u64> {
        self.clock.deadline
    }

    /// Bytes the receiver has acknowledged (by asking for later ones,
    /// or with EOMA): the error queue's `J1939_NLA_BYTES_ACKED`.
    pub fn acked_bytes(&self) -> u32 {
        self.acked.saturating_mul(7).min(self.size as u32)
    }

    fn ctl_id(&self) -> Id {
        Id {
            pgn: self.kind.ctl_pgn(),
            ..self.id
        }
    }

    fn finish(&mut self, o: Outcome) -> Step {
        self.st = TxSt::Done;
        Step {
            done: Some(o),
            timer: self.clock.cancel(),
            ..Step::NONE
        }
    }

    /// Aborts with `code`: the abort frame goes to the responder (none
    /// for BAM), the socket gets the code's errno. (mainline: the
    /// session then waits up to 500 ms for its abort's echo before it
    /// is released; ours ends at once.)
    fn abort(&mut self, code: u8) -> Step {
        let mut s = self.finish(Outcome::Aborted {
            errno: abort_errno(code),
            reason: Some(code),
        });
        if self.kind != Kind::Bam {
            s.frame = Some(abort_frame(
                self.kind == Kind::Etp,
                self.id.prio,
                self.id.sa,
                self.id.da,
                code,
                self.id.pgn,
            ));
        }
        s
    }

    /// The next data packet of `data`, and the timer after it.
    fn send_dat(&mut self, data: &[u8], now: u64) -> Step {
        let start = self.tx as usize * 7;
        let Some(chunk) = data
            .get(start..self.size.min(data.len()))
            .filter(|c| !c.is_empty() && data.len() == self.size)
        else {
            // Not the buffer the session started with.
            return self.abort(abort::OTHER);
        };
        let n = chunk.len().min(7);
        let mut d = [0xffu8; 8];
        d[0] = (self.tx - self.dpo + 1) as u8;
        d[1..1 + n].copy_from_slice(&chunk[..n]);
        let id = Id {
            pgn: self.kind.dat_pgn(),
            ..self.id
        };
        let f = Frame::new(id, &d);
        self.tx += 1;
        let timer = if self.tx < self.last {
            let gap = if self.kind == Kind::Bam {
                BAM_GAP_NS
            } else {
                self.packet_delay
            };
            self.clock.arm(now.saturating_add(gap), Due::Send)
        } else {
            // The window (or BAM) is out: wait for the echo of its last
            // packet, then (unicast) for CTS or EOMA.
            self.st = TxSt::WaitCts;
            self.echo_pending = true;
            self.clock.arm(now.saturating_add(ECHO_NS), Due::Timeout)
        };
        Step {
            frame: self.clock.sent(f),
            timer,
            ..Step::NONE
        }
    }

    /// A control frame from the responder (CTS, EOMA, abort; `d` its 8
    /// bytes; see [`classify`] and [`Key::tx_of_reply`]) at `now`;
    /// `data` is the message being sent.
    pub fn on_ctl(&mut self, d: &[u8; 8], data: &[u8], now: u64) -> Step {
        if self.st == TxSt::Done || self.kind == Kind::Bam {
            return Step::NONE;
        }
        let cmd = d[0];
        let etp = self.kind == Kind::Etp;
        let pgn = ctl_pgn(d);
        if pgn != self.id.pgn {
            // About another session of this pair: answer for that one.
            return Step {
                frame: bad_pgn_abort(cmd)
                    .map(|c| abort_frame(etp, self.id.prio, self.id.sa, self.id.da, c, pgn)),
                ..Step::NONE
            };
        }
        self.clock.retries = 0;
        match cmd {
            CMD_ABORT => self.finish(Outcome::Aborted {
                errno: abort_errno(d[1]),
                reason: Some(d[1]),
            }),
            TP_CMD_EOMA | ETP_CMD_EOMA if (cmd == ETP_CMD_EOMA) == etp => {
                self.acked = self.total;
                self.finish(Outcome::Sent)
            }
            TP_CMD_CTS if !etp => self.on_cts(u32::from(d[1]), u32::from(d[2]), data, now),
            ETP_CMD_CTS if etp => self.on_cts(u32::from(d[1]), le24(&d[2..5]), data, now),
            _ => Step::NONE,
        }
    }

    fn on_cts(&mut self, n: u32, next: u32, data: &[u8], now: u64) -> Step {
        if self.st == TxSt::Sending {
            // (mainline: restarts the window from the CTS.)
            return self.abort(abort::GENERIC);
        }
        if n == 0 {
            // Hold: the receiver asks us to wait (repeatedly, if it
            // likes: mainline would abort a second CTS(0) with reason 8).
            // A hold asks for no packet, so its next-packet byte names
            // none (receivers send 0xFF there; mainline takes any value
            // but 0): it is not checked, and the position stays until a
            // CTS asks for packets.
            self.echo_pending = false;
            return Step {
                timer: self.clock.arm(now.saturating_add(T4_NS), Due::Timeout),
                ..Step::NONE
            };
        }
        if next == 0 || n > self.block {
            return self.abort(abort::FAULT);
        }
        if next > self.total {
            // (mainline: sends nothing and times out.)
            return self.abort(abort::ECTS_TOO_BIG);
        }
        let acked = next - 1;
        self.acked = acked;
        self.tx = acked;
        self.echo_pending = false;
        // Progress reported for a window after the first, as mainline
        // does (not for holds).
        let notify = (acked > 0).then(|| Notify::TxSched((acked * 7).min(self.size as u32)));
        self.last = (acked + n).min(self.total);
        self.st = TxSt::Sending;
        let mut s = if self.kind == Kind::Etp {
            self.dpo = acked;
            let off = acked.to_le_bytes();
            let f = ctl(
                self.ctl_id(),
                [
                    ETP_CMD_DPO,
                    (self.last - acked) as u8,
                    off[0],
                    off[1],
                    off[2],
                ],
                self.id.pgn,
            );
            Step {
                frame: self.clock.sent(f),
                timer: self.clock.arm(now, Due::Send),
                ..Step::NONE
            }
        } else {
            self.send_dat(data, now)
        };
        s.notify = notify;
        s
    }

    /// The echo of a data packet we sent (its 8 bytes) came back at
    /// `now`: for BAM the last one ends the session; for the others the
    /// last one of a window starts T3.
    pub fn on_echo(&mut self, d: &[u8], now: u64) -> Step {
        if self.st != TxSt::WaitCts || !self.echo_pending {
            return Step::NONE;
        }
        let last_seq = (self.last.wrapping_sub(self.dpo)) as u8;
        if d.first() != Some(&last_seq) {
            return Step::NONE;
        }
        self.echo_pending = false;
        self.clock.retries = 0;
        if self.kind == Kind::Bam {
            self.acked = self.total;
            return self.finish(Outcome::Sent);
        }
        Step {
            timer: self.clock.arm(now.saturating_add(T3_NS), Due::Timeout),
            ..Step::NONE
        }
    }

    /// The timer expired at `now` (early calls do nothing): the next
    /// packet, a retry, or a timeout (abort [`abort::TIMEOUT`]).
    pub fn on_timer(&mut self, data: &[u8], now: u64) -> Step {
        if self.st == TxSt::Done || !self.clock.due(now) {
            return Step::NONE;
        }
        match self.clock.due {
            Due::Retry => self.clock.retry(now),
            Due::Timeout => self.abort(abort::TIMEOUT),
            Due::Send if self.st == TxSt::Sending => self.send_dat(data, now),
            Due::Send => Step {
                timer: self.clock.cancel(),
                ..Step::NONE
            },
        }
    }

    /// The device refused the frame of the last step (queue full) at
    /// `now`: it is sent again after 10 ms plus `jitter_ms` (0..=15);
    /// after [`RETRY_LIMIT`] refusals in a row the session ends with
    /// `ENETUNREACH` and no abort frame (mainline).
    pub fn on_refused(&mut self, now: u64, jitter_ms: u8) -> Step {
        self.refused_step(now, jitter_ms)
    }

    /// Ends the session from outside (socket closed, interface down):
    /// `errno` for the socket (mainline: `ESHUTDOWN`, no abort frame);
    /// with `code`, an abort frame with that reason goes out (not for
    /// BAM).
    pub fn cancel(&mut self, errno: i32, code: Option<u8>) -> Step {
        self.cancel_step(errno, code)
    }
}

impl SessionEnd for TxSession {
    fn is_done(&self) -> bool {
        self.st == TxSt::Done
    }

    fn clock_mut(&mut self) -> &mut Clock {
        &mut self.clock
    }

    fn end(&mut self, o: Outcome) -> Step {
        self.finish(o)
    }

    /// The originator aborts from its source to its destination.
    fn abort_route(&self) -> (Kind, u8, u8, u8, u32) {
        (self.kind, self.id.prio, self.id.sa, self.id.da, self.id.pgn)
    }
}

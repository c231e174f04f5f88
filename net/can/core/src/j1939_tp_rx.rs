// SPDX-License-Identifier: GPL-2.0
//! The J1939 transport receiver (responder, or a listener of a BAM) of
//! one message, as a pure state machine over virtual time (mainline's
//! receive side of `net/can/j1939/transport.c`, rewritten). The shared
//! parts, the timeouts and where we differ from mainline are in
//! [`super::j1939_tp`] and Documentation/networking/rcan/j1939.rst,
//! "Mainline or the standard".
//!
//! One [`RxSession`] exists per message being received; it reassembles
//! into the buffer the caller passes to every data event (never writing
//! outside the announced size). The caller serializes the events of a
//! session.

use super::j1939::{Id, MAX_ETP_SIZE, MAX_TP_SIZE, MIN_TP_SIZE};
use super::j1939_tp::{
    abort, abort_errno, abort_frame, bad_pgn_abort, ctl, ctl_pgn, le24, packets, Clock, Due, Key,
    Kind, Notify, Outcome, Params, SessionEnd, Step, CMD_ABORT, ETP_CMD_CTS, ETP_CMD_DPO,
    ETP_CMD_EOMA, ETP_CMD_RTS, ETP_PGN_CTL, T1_NS, T2_NS, TP_CMD_BAM, TP_CMD_CTS, TP_CMD_EOMA,
    TP_CMD_RTS,
};

/// The states of a receiver.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum RxSt {
    /// ETP: a CTS is out, the DPO must come first.
    WaitDpo,
    /// Waiting for the packets `rx..last`.
    WaitData,
    /// Ended.
    Done,
}

/// A receiver's session (the responder, or any listener of a BAM).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RxSession {
    kind: Kind,
    /// sa: the originator; da: us (0xFF for BAM); pgn: the message's.
    id: Id,
    size: usize,
    total: u32,
    /// The most packets per CTS: the originator's limit and ours.
    block: u32,
    /// Next packet expected (0-based); packets before it are in the
    /// buffer.
    rx: u32,
    /// End of the current window.
    last: u32,
    dpo: u32,
    /// Of our last CTS: the packet it asked for first, and how many.
    cts_next: u32,
    cts_n: u32,
    st: RxSt,
    clock: Clock,
}

impl RxSession {
    /// An RTS or BAM (`d`, its 8 bytes; `id` its addressing: sa the
    /// originator, da us or 0xFF) arrived at `now`, and no session with
    /// its key is active; `buf_len` is the reassembly buffer the caller
    /// has for it. `Ok`: the session and its first step (CTS, or the T1
    /// wait of a BAM), with [`Notify::RxRts`]. `Err`: no session, and the
    /// step to take (an abort frame to the originator, none for BAM):
    ///
    /// - TP: over 1785 bytes [`abort::FAULT`] (mainline; the standard
    ///   says [`abort::EDPO_UNEXPECTED`]), over `max_size` or `buf_len`
    ///   [`abort::RESOURCE`], under 9 bytes or a packet count that does
    ///   not fit the size [`abort::FAULT`] (mainline trusts the count);
    /// - ETP: over 117,440,505 [`abort::FAULT`], over `max_size` or
    ///   `buf_len` [`abort::RESOURCE`], 1785 or fewer [`abort::FAULT`].
    ///
    /// Commands other than RTS/BAM, and BAM to a unicast address or RTS
    /// to broadcast, give `Err` with no frame.
    pub fn on_rts(
        p: &Params,
        id: Id,
        d: &[u8; 8],
        buf_len: usize,
        now: u64,
    ) -> Result<(RxSession, Step), Step> {
        let etp = id.pgn == ETP_PGN_CTL;
        let kind = match (d[0], etp) {
            (TP_CMD_RTS, false) if !id.is_broadcast() => Kind::Tp,
            (TP_CMD_BAM, false) if id.is_broadcast() => Kind::Bam,
            (ETP_CMD_RTS, true) if !id.is_broadcast() => Kind::Etp,
            _ => return Err(Step::NONE),
        };
        let pgn = ctl_pgn(d);
        let size = if etp {
            u32::from_le_bytes([d[1], d[2], d[3], d[4]]) as usize
        } else {
            usize::from(u16::from_le_bytes([d[1], d[2]]))
        };
        let total = packets(size);
        let code = if etp {
            if size > MAX_ETP_SIZE {
                Some(abort::FAULT)
            } else if size > p.max_size || size > buf_len {
                Some(abort::RESOURCE)
            } else if size <= MAX_TP_SIZE {
                Some(abort::FAULT)
            } else {
                None
            }
        } else if size > MAX_TP_SIZE {
            Some(abort::FAULT)
        } else if size > p.max_size || size > buf_len {
            Some(abort::RESOURCE)
        } else if size < MIN_TP_SIZE || u32::from(d[3]) != total {
            Some(abort::FAULT)
        } else {
            None
        };
        if let Some(c) = code {
            return Err(Step {
                frame: (kind != Kind::Bam).then(|| abort_frame(etp, id.prio, id.da, id.sa, c, pgn)),
                ..Step::NONE
            });
        }
        let theirs = match kind {
            Kind::Etp => 255,
            // 0 is not a limit the standard knows: no limit.
            _ if d[4] == 0 => 255,
            _ => u32::from(d[4]),
        };
        let ours = u32::from(p.block.max(1));
        let mut s = RxSession {
            kind,
            id: Id { pgn, ..id },
            size,
            total,
            block: theirs.min(ours),
            rx: 0,
            last: 0,
            dpo: 0,
            cts_next: 0,
            cts_n: 0,
            st: RxSt::WaitData,
            clock: Clock::new(),
        };
        let mut step = if kind == Kind::Bam {
            s.last = total;
            Step {
                timer: s.clock.arm(now.saturating_add(T1_NS), Due::Timeout),
                ..Step::NONE
            }
        } else {
            s.send_cts(now)
        };
        step.notify = Some(Notify::RxRts);
        Ok((s, step))
    }

    /// The reassembly buffer an RTS or BAM (`d`, on the control PGN of
    /// `id`) needs: its announced size when [`RxSession::on_rts`] would
    /// take it given a buffer that large, `None` when it refuses it
    /// whatever the buffer (a size or packet count out of range, over
    /// `p.max_size`, a command that starts nothing). So the caller
    /// allocates only for a message that may come, and passes
    /// `usize::MAX` as `buf_len` for one that may not (the refusal, and
    /// its abort code, are then the same as with any buffer).
    pub fn wanted_buffer(p: &Params, id: Id, d: &[u8; 8]) -> Option<usize> {
        RxSession::on_rts(p, id, d, usize::MAX, 0)
            .ok()
            .map(|(s, _)| s.size)
    }

    /// The transport.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// The message's addressing: sa the originator, da us (or 0xFF),
    /// the PGN and priority of the RTS.
    pub fn id(&self) -> Id {
        self.id
    }

    /// The announced size.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The session's key.
    pub fn key(&self) -> Key {
        Key {
            sa: self.id.sa,
            da: self.id.da,
            etp: self.kind == Kind::Etp,
            tx: false,
        }
    }

    /// Whether the session ended.
    pub fn is_done(&self) -> bool {
        self.st == RxSt::Done
    }

    /// The timer's deadline, if armed.
    pub fn deadline(&self) -> Option<u64> {
        self.clock.deadline
    }

    /// Bytes in the buffer so far (in order from the start).
    pub fn received(&self) -> usize {
        (self.rx as usize * 7).min(self.size)
    }

    fn reply_id(&self) -> Id {
        Id {
            prio: self.id.prio,
            pgn: self.kind.ctl_pgn(),
            sa: self.id.da,
            da: self.id.sa,
        }
    }

    fn finish(&mut self, o: Outcome) -> Step {
        self.st = RxSt::Done;
        Step {
            done: Some(o),
            timer: self.clock.cancel(),
            ..Step::NONE
        }
    }

    fn abort(&mut self, code: u8) -> Step {
        let mut s = self.finish(Outcome::Aborted {
            errno: abort_errno(code),
            reason: Some(code),
        });
        if self.kind != Kind::Bam {
            s.frame = Some(abort_frame(
                self.kind == Kind::Etp,
                self.id.prio,
                self.id.da,
                self.id.sa,
                code,
                self.id.pgn,
            ));
        }
        s
    }

    /// CTS for the next window (never a hold: mainline's receiver holds
    /// nothing).
    fn send_cts(&mut self, now: u64) -> Step {
        let n = (self.total - self.rx).min(self.block);
        let next = self.rx + 1;
        self.cts_next = next;
        self.cts_n = n;
        let head = if self.kind == Kind::Etp {
            let b = next.to_le_bytes();
            self.st = RxSt::WaitDpo;
            [ETP_CMD_CTS, n as u8, b[0], b[1], b[2]]
        } else {
            self.st = RxSt::WaitData;
            self.last = self.rx + n;
            [TP_CMD_CTS, n as u8, next as u8, 0xff, 0xff]
        };
        let f = ctl(self.reply_id(), head, self.id.pgn);
        Step {
            frame: self.clock.sent(f),
            timer: self.clock.arm(now.saturating_add(T2_NS), Due::Timeout),
            ..Step::NONE
        }
    }

    /// A control frame from the originator for this session's key (`d`
    /// its 8 bytes) at `now`: abort, DPO, or a second RTS/BAM.
    pub fn on_ctl(&mut self, d: &[u8; 8], now: u64) -> Step {
        if self.st == RxSt::Done {
            return Step::NONE;
        }
        let cmd = d[0];
        let etp = self.kind == Kind::Etp;
        let pgn = ctl_pgn(d);
        if pgn != self.id.pgn {
            let code = if self.kind == Kind::Bam {
                None
            } else {
                bad_pgn_abort(cmd)
            };
            return Step {
                frame: code.map(|c| abort_frame(etp, self.id.prio, self.id.da, self.id.sa, c, pgn)),
                ..Step::NONE
            };
        }
        self.clock.retries = 0;
        match cmd {
            CMD_ABORT => self.finish(Outcome::Aborted {
                errno: abort_errno(d[1]),
                reason: Some(d[1]),
            }),
            // A second RTS (or BAM) for a running session: both end
            // (mainline: the running one is aborted with "busy", the new
            // one is not started).
            TP_CMD_RTS | TP_CMD_BAM | ETP_CMD_RTS => self.abort(abort::BUSY),
            ETP_CMD_DPO if etp => {
                if self.st != RxSt::WaitDpo {
                    return self.abort(abort::EDPO_UNEXPECTED);
                }
                let n = u32::from(d[1]);
                let off = le24(&d[2..5]);
                if n > self.cts_n {
                    return self.abort(abort::EDPO_OUTOF_CTS);
                }
                if off != self.cts_next - 1 {
                    return self.abort(abort::BAD_EDPO_OFFSET);
                }
                self.dpo = off;
                self.last = off + n;
                self.st = RxSt::WaitData;
                Step {
                    timer: self.clock.arm(now.saturating_add(T1_NS), Due::Timeout),
                    notify: Some(Notify::RxDpo),
                    ..Step::NONE
                }
            }
            _ => Step::NONE,
        }
    }

    /// A data packet (`d`, its payload) from the originator at `now`,
    /// written into `buf` (the reassembly buffer, at least
    /// [`RxSession::size`] bytes; never written outside `..size`).
    /// In-order packets are stored; a duplicate or one after a gap is
    /// ignored (the session then times out, as on mainline).
    pub fn on_dat(&mut self, d: &[u8], buf: &mut [u8], now: u64) -> Step {
        if self.st == RxSt::Done {
            return Step::NONE;
        }
        if d.len() != 8 {
            return self.abort(abort::UNEXPECTED_DATA);
        }
        if self.st != RxSt::WaitData {
            return self.abort(abort::FAULT);
        }
        self.clock.retries = 0;
        let seq = u32::from(d[0]);
        if seq == 0 {
            return self.wait_more(now);
        }
        let packet = seq - 1 + self.dpo;
        if packet >= self.total {
            return self.abort(abort::FAULT);
        }
        if packet != self.rx || packet >= self.last {
            return self.wait_more(now);
        }
        let start = packet as usize * 7;
        let end = (start + 7).min(self.size);
        let Some(dst) = buf.get_mut(start..end) else {
            return self.abort(abort::RESOURCE);
        };
        let n = dst.len();
        dst.copy_from_slice(&d[1..1 + n]);
        self.rx += 1;
        if self.rx < self.last {
            return self.wait_more(now);
        }
        if self.kind == Kind::Bam {
            return self.finish(Outcome::Delivered(self.size));
        }
        if self.rx < self.total {
            return self.send_cts(now);
        }
        // Ours is delivered when the EOMA goes out (mainline: when its
        // echo comes back).
        let sz = (self.size as u32).to_le_bytes();
        let head = if self.kind == Kind::Etp {
            [ETP_CMD_EOMA, sz[0], sz[1], sz[2], sz[3]]
        } else {
            [TP_CMD_EOMA, sz[0], sz[1], self.total as u8, 0xff]
        };
        let f = ctl(self.reply_id(), head, self.id.pgn);
        let mut s = self.finish(Outcome::Delivered(self.size));
        s.frame = self.clock.sent(f);
        s
    }

    fn wait_more(&mut self, now: u64) -> Step {
        Step {
            timer: self.clock.arm(now.saturating_add(T1_NS), Due::Timeout),
            ..Step::NONE
        }
    }

    /// The timer expired at `now` (early calls do nothing): a retry, or
    /// a timeout (abort [`abort::TIMEOUT`], no frame for BAM).
    pub fn on_timer(&mut self, now: u64) -> Step {
        if self.st == RxSt::Done || !self.clock.due(now) {
            return Step::NONE;
        }
        match self.clock.due {
            Due::Retry => self.clock.retry(now),
            _ => self.abort(abort::TIMEOUT),
        }
    }

    /// The device refused the frame of the last step: as
    /// [`TxSession::on_refused`]. A refused EOMA is not retried (the
    /// message was delivered; the originator times out).
    pub fn on_refused(&mut self, now: u64, jitter_ms: u8) -> Step {
        self.refused_step(now, jitter_ms)
    }

    /// Ends the session from outside, as [`TxSession::cancel`].
    pub fn cancel(&mut self, errno: i32, code: Option<u8>) -> Step {
        self.cancel_step(errno, code)
    }
}

impl SessionEnd for RxSession {
    fn is_done(&self) -> bool {
        self.st == RxSt::Done
    }

    fn clock_mut(&mut self) -> &mut Clock {
        &mut self.clock
    }

    fn end(&mut self, o: Outcome) -> Step {
        self.finish(o)
    }

    /// The responder aborts back to the originator.
    fn abort_route(&self) -> (Kind, u8, u8, u8, u32) {
        (self.kind, self.id.prio, self.id.da, self.id.sa, self.id.pgn)
    }
}

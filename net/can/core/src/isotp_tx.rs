// SPDX-License-Identifier: GPL-2.0
//! The ISO-TP sender of one socket as a pure state machine over virtual
//! time: mainline's `isotp_sendmsg`, `isotp_rcv_fc`, `isotp_rcv_echo`,
//! `isotp_send_cframe` and its three transmit timers, rewritten.
//! Documentation/networking/rcan/isotp.rst, "Sender".
//!
//! One [`Tx`] exists per socket. It holds the position in the PDU, not
//! the PDU: the caller keeps the PDU in its own buffer and passes the same
//! bytes to every event of a transfer. Each event returns a [`TxStep`]:
//! at most one frame to send, what to do with the one transmit timer
//! (absolute deadlines, see [`TimerCmd`]), and the transfer's result when
//! it ends. The caller serializes all calls (the module holds the
//! socket's receive lock, a spinlock taken with bottom halves off);
//! nothing here sleeps or allocates, so any context may call it: in the
//! module [`Tx::start`] runs in process context (`sendmsg`), the others
//! in softirq context (frame reception, echo, hrtimer).
//!
//! The timer serves one purpose at a time, told by the state: waiting for
//! a flow control frame (N_Bs, 1 s by default, `ECOMM`), for the echo
//! of a sent frame (2 s by default, `ECOMM`; both [`Config::timeouts`]), or for the STmin gap before the next
//! consecutive frame. As in mainline one frame is in flight at a time:
//! the next consecutive frame goes out when the previous one's echo came
//! back (at once, or after the gap).

use super::arb::EINVAL;
use super::isotp::{
    Config, TimerCmd, CAN_ISOTP_CF_BROADCAST, CAN_ISOTP_DYN_FC_PARMS, CAN_ISOTP_FORCE_TXSTMIN,
    EAGAIN, EBADMSG, ECOMM, EMSGSIZE,
};
use super::isotp_pci::{
    parse_fc, sf_max, stmin_ns, stmin_valid, write_cf, write_ff, write_sf, LlFrame, FS_CTS,
    FS_OVFLW, FS_WAIT,
};

/// What the caller does after a sender event.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct TxStep {
    /// A frame to send now (with the socket's `tx_id` and `tx_flags`).
    pub frame: Option<LlFrame>,
    /// Whether the caller must report that frame's echo (its own
    /// loopback) with [`Tx::on_echo`]; false for a first frame that waits
    /// for flow control, as in mainline.
    pub wants_echo: bool,
    /// The transmit timer.
    pub timer: TimerCmd,
    /// The transfer ended: `Ok` when the last frame's echo came back, or
    /// the errno (`ECOMM`, `EBADMSG`, `EMSGSIZE`, `EINVAL`) that the
    /// socket reports as its error.
    pub done: Option<Result<(), i32>>,
}

/// What the caller does after a sender event of the `_into` methods
/// ([`Tx::start_into`], [`Tx::on_fc_into`], [`Tx::on_echo_into`],
/// [`Tx::on_timer_into`]): a [`TxStep`] whose frame the machine wrote
/// into the caller's buffer (see [`LlFrame`]) instead of returning it, so
/// that the per-frame path moves no frame by value. The module uses
/// these; the by-value methods wrap them.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct TxAction {
    /// The caller's buffer holds a frame to send now ([`TxStep::frame`]).
    pub frame: bool,
    /// See [`TxStep::wants_echo`].
    pub wants_echo: bool,
    /// See [`TxStep::timer`].
    pub timer: TimerCmd,
    /// See [`TxStep::done`].
    pub done: Option<Result<(), i32>>,
}

impl TxAction {
    const NONE: TxAction = TxAction {
        frame: false,
        wants_echo: false,
        timer: TimerCmd::Keep,
        done: None,
    };

    /// The by-value step, with the frame `f` the action wrote.
    pub fn step(&self, f: &LlFrame) -> TxStep {
        TxStep {
            frame: self.frame.then_some(*f),
            wants_echo: self.wants_echo,
            timer: self.timer,
            done: self.done,
        }
    }
}

impl TxStep {
    const NONE: TxStep = TxStep {
        frame: None,
        wants_echo: false,
        timer: TimerCmd::Keep,
        done: None,
    };
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum St {
    Idle,
    /// The FF is out; BS and STmin come with the first FC.
    WaitFirstFc,
    /// A block is done (or a wait frame came); waiting for the next FC.
    WaitFc,
    /// Sending an SF or CFs: waiting for an echo (`echo_pending`) or for
    /// the STmin gap to pass.
    Sending,
}

/// The sender of one socket; owned by the socket, protected by its
/// receive lock in the module.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Tx {
    st: St,
    /// PDU length of the running transfer.
    len: usize,
    /// Bytes of the PDU sent so far.
    idx: usize,
    /// Sequence number of the next CF.
    sn: u8,
    /// CFs sent in the current block.
    bs: u8,
    /// Block size from the flow control frame (0: no more FCs).
    fc_bs: u8,
    /// Gap before each CF after the previous one's echo, ns: N_As
    /// (`frame_txtime`) plus STmin (received or forced).
    gap: u64,
    /// A frame whose echo we wait for is out.
    echo_pending: bool,
    /// The first bytes of that frame (at most 4, `echo_tag_len`), which
    /// its echo must repeat: the socket's own flow control frames go out
    /// on the same identifier (the receiver's, for the other direction)
    /// and their echoes are not this one's (mainline's `cfecho`).
    echo_tag: [u8; 4],
    echo_tag_len: u8,
    /// When the timer expires, if armed.
    deadline: Option<u64>,
}

impl Default for Tx {
    fn default() -> Self {
        Self::new()
    }
}

impl Tx {
    /// An idle sender.
    pub const fn new() -> Self {
        Tx {
            st: St::Idle,
            len: 0,
            idx: 0,
            sn: 0,
            bs: 0,
            fc_bs: 0,
            gap: 0,
            echo_pending: false,
            echo_tag: [0; 4],
            echo_tag_len: 0,
            deadline: None,
        }
    }

    /// Records that `f`, just written, goes out and its echo is awaited.
    fn await_echo(&mut self, f: &LlFrame) {
        let n = usize::from(f.len).min(4);
        self.echo_tag[..n].copy_from_slice(&f.data[..n]);
        self.echo_tag_len = n as u8;
        self.echo_pending = true;
    }

    /// Whether `echo`, the payload of one of this socket's own frames on
    /// its transmit identifier coming back, is the echo of the frame we
    /// wait for (not, say, of a flow control frame our receiver sent for
    /// the other direction, nor a late one of an earlier transfer's
    /// frame: its first bytes, the PCI with the sequence number, differ).
    pub fn echo_matches(&self, echo: &[u8]) -> bool {
        let n = usize::from(self.echo_tag_len);
        self.echo_pending && echo.get(..n) == Some(&self.echo_tag[..n])
    }

    /// Whether no transfer is running (a new `sendmsg` may start one;
    /// `poll` reports writable only then).
    pub fn is_idle(&self) -> bool {
        self.st == St::Idle
    }

    /// Bytes of the running transfer's PDU sent so far (0 when idle).
    pub fn sent(&self) -> usize {
        if self.is_idle() {
            0
        } else {
            self.idx
        }
    }

    /// The timer's deadline, if armed.
    pub fn deadline(&self) -> Option<u64> {
        self.deadline
    }

    fn timer(&mut self, cmd: TimerCmd) -> TimerCmd {
        self.deadline = match cmd {
            TimerCmd::Arm(at) => Some(at),
            TimerCmd::Cancel => None,
            TimerCmd::Keep => self.deadline,
        };
        cmd
    }

    fn finish(&mut self, res: Result<(), i32>) -> TxAction {
        self.st = St::Idle;
        self.echo_pending = false;
        TxAction {
            done: Some(res),
            timer: self.timer(TimerCmd::Cancel),
            ..TxAction::NONE
        }
    }

    /// Starts sending `pdu` at `now`: a single frame if it fits TX_DL,
    /// else a first frame (then consecutive frames as flow control
    /// allows; with only [`CAN_ISOTP_CF_BROADCAST`] without waiting for
    /// any). `EAGAIN` while a transfer runs; `EINVAL` for an empty PDU,
    /// one of 4 GiB or more (FF_DL has 32 bits), or a PDU too long for a
    /// single frame with only `CAN_ISOTP_SF_BROADCAST`. The caller checks
    /// `max_pdu_size` first ([`Config::check_send_len`]).
    pub fn start(&mut self, cfg: &Config, pdu: &[u8], now: u64) -> Result<TxStep, i32> {
        let mut f = LlFrame::default();
        let a = self.start_into(cfg, pdu, now, &mut f)?;
        Ok(a.step(&f))
    }

    /// [`Tx::start`], the frame written into `out` ([`TxAction`]).
    pub fn start_into(
        &mut self,
        cfg: &Config,
        pdu: &[u8],
        now: u64,
        out: &mut LlFrame,
    ) -> Result<TxAction, i32> {
        if !self.is_idle() {
            return Err(EAGAIN);
        }
        if pdu.is_empty() || u32::try_from(pdu.len()).is_err() {
            return Err(EINVAL);
        }
        cfg.check_send_len(pdu.len(), u32::MAX)?;
        self.len = pdu.len();
        self.bs = 0;
        let (wants_echo, timeout);
        if pdu.len() <= sf_max(cfg) {
            write_sf(cfg, pdu, out);
            self.idx = pdu.len();
            self.st = St::Sending;
            wants_echo = true;
            timeout = cfg.timeouts.echo_ns;
        } else {
            self.idx = write_ff(cfg, pdu.len(), pdu, out);
            self.sn = 1;
            if cfg.bc_flags() == CAN_ISOTP_CF_BROADCAST {
                // No flow control: STmin 0 (or forced), no blocks.
                self.gap = if cfg.has(CAN_ISOTP_FORCE_TXSTMIN) {
                    u64::from(cfg.force_tx_stmin)
                } else {
                    u64::from(cfg.frame_txtime)
                };
                self.fc_bs = 0;
                self.st = St::Sending;
                wants_echo = true;
                timeout = cfg.timeouts.echo_ns;
            } else {
                self.st = St::WaitFirstFc;
                wants_echo = false;
                timeout = cfg.timeouts.fc_ns;
            }
        }
        if wants_echo {
            self.await_echo(out);
        } else {
            self.echo_pending = false;
        }
        Ok(TxAction {
            frame: true,
            wants_echo,
            timer: self.timer(TimerCmd::Arm(now.saturating_add(timeout))),
            done: None,
        })
    }

    /// Sends the next consecutive frame of `pdu` and arms the echo
    /// timeout.
    fn send_cf(&mut self, cfg: &Config, pdu: &[u8], now: u64, out: &mut LlFrame) -> TxAction {
        let Some(rest) = pdu.get(self.idx..self.len).filter(|r| !r.is_empty()) else {
            // The caller passed another PDU than the one it started.
            return self.finish(Err(EINVAL));
        };
        let n = write_cf(cfg, self.sn, rest, out);
        self.idx += n;
        self.sn = (self.sn + 1) & 0x0F;
        self.bs = self.bs.wrapping_add(1);
        self.await_echo(out);
        TxAction {
            frame: true,
            wants_echo: true,
            timer: self.timer(TimerCmd::Arm(now.saturating_add(cfg.timeouts.echo_ns))),
            done: None,
        }
    }

    /// A flow control frame for this socket arrived at `now` (`data`: the
    /// frame's payload, address byte included; see
    /// [`super::isotp::route`]). Ignored unless we wait for one. A
    /// malformed one ends the transfer with `EBADMSG`; BS and STmin are
    /// taken from the first FC of a transfer (from every FC with
    /// [`CAN_ISOTP_DYN_FC_PARMS`]); a reserved STmin counts as 127 ms.
    /// Flow status: continue (send the next block), wait (wait up to 1 s
    /// more; any number of wait frames is accepted, as in mainline),
    /// overflow (`EMSGSIZE`), anything else (`EBADMSG`).
    pub fn on_fc(&mut self, cfg: &Config, data: &[u8], pdu: &[u8], now: u64) -> TxStep {
        let mut f = LlFrame::default();
        self.on_fc_into(cfg, data, pdu, now, &mut f).step(&f)
    }

    /// [`Tx::on_fc`], the frame written into `out` ([`TxAction`]).
    pub fn on_fc_into(
        &mut self,
        cfg: &Config,
        data: &[u8],
        pdu: &[u8],
        now: u64,
        out: &mut LlFrame,
    ) -> TxAction {
        if self.st != St::WaitFirstFc && self.st != St::WaitFc {
            return TxAction::NONE;
        }
        let Ok(fc) = parse_fc(cfg, data) else {
            return self.finish(Err(EBADMSG));
        };
        if self.st == St::WaitFirstFc || cfg.has(CAN_ISOTP_DYN_FC_PARMS) {
            self.fc_bs = fc.bs;
            let stmin = if stmin_valid(fc.stmin) {
                fc.stmin
            } else {
                0x7F
            };
            let st = if cfg.has(CAN_ISOTP_FORCE_TXSTMIN) {
                cfg.force_tx_stmin
            } else {
                stmin_ns(stmin)
            };
            self.gap = u64::from(cfg.frame_txtime) + u64::from(st);
            self.st = St::WaitFc;
        }
        match fc.fs {
            FS_CTS => {
                self.bs = 0;
                self.st = St::Sending;
                self.send_cf(cfg, pdu, now, out)
            }
            FS_WAIT => TxAction {
                timer: self.timer(TimerCmd::Arm(now.saturating_add(cfg.timeouts.fc_ns))),
                ..TxAction::NONE
            },
            FS_OVFLW => self.finish(Err(EMSGSIZE)),
            _ => self.finish(Err(EBADMSG)),
        }
    }

    /// The echo of the last frame we asked to be told about
    /// ([`TxStep::wants_echo`]) arrived at `now`: the transfer is done, or
    /// a block is complete (wait for FC), or the next consecutive frame
    /// goes out (at once with a zero gap, else when the timer expires).
    /// Ignored when no such echo is awaited.
    pub fn on_echo(&mut self, cfg: &Config, pdu: &[u8], now: u64) -> TxStep {
        let mut f = LlFrame::default();
        self.on_echo_into(cfg, pdu, now, &mut f).step(&f)
    }

    /// [`Tx::on_echo`], the frame written into `out` ([`TxAction`]).
    pub fn on_echo_into(
        &mut self,
        cfg: &Config,
        pdu: &[u8],
        now: u64,
        out: &mut LlFrame,
    ) -> TxAction {
        if self.st != St::Sending || !self.echo_pending {
            return TxAction::NONE;
        }
        self.echo_pending = false;
        if self.idx >= self.len {
            return self.finish(Ok(()));
        }
        if self.fc_bs != 0 && self.bs >= self.fc_bs {
            self.st = St::WaitFc;
            return TxAction {
                timer: self.timer(TimerCmd::Arm(now.saturating_add(cfg.timeouts.fc_ns))),
                ..TxAction::NONE
            };
        }
        if self.gap == 0 {
            return self.send_cf(cfg, pdu, now, out);
        }
        TxAction {
            timer: self.timer(TimerCmd::Arm(now.saturating_add(self.gap))),
            ..TxAction::NONE
        }
    }

    /// One of this socket's own frames on its transmit identifier came
    /// back (payload `echo`, address byte included) at `now`: the echo
    /// [`Tx::on_echo`] waits for if it is that frame's
    /// ([`Tx::echo_matches`]), else nothing (the echo of a flow control
    /// frame the socket's receiver sent). What the module calls for
    /// every own frame.
    pub fn on_own_frame(&mut self, cfg: &Config, echo: &[u8], pdu: &[u8], now: u64) -> TxStep {
        let mut f = LlFrame::default();
        self.on_own_frame_into(cfg, echo, pdu, now, &mut f).step(&f)
    }

    /// [`Tx::on_own_frame`], the frame written into `out` ([`TxAction`]).
    #[inline]
    pub fn on_own_frame_into(
        &mut self,
        cfg: &Config,
        echo: &[u8],
        pdu: &[u8],
        now: u64,
        out: &mut LlFrame,
    ) -> TxAction {
        if !self.echo_matches(echo) {
            return TxAction::NONE;
        }
        self.on_echo_into(cfg, pdu, now, out)
    }

    /// The transmit timer fired at `now`. Before the deadline (a stale
    /// expiry) or with none armed: ignored. Else, after an STmin gap the
    /// next consecutive frame goes out; while waiting for flow control or
    /// an echo the transfer ends with `ECOMM`.
    pub fn on_timer(&mut self, cfg: &Config, pdu: &[u8], now: u64) -> TxStep {
        let mut f = LlFrame::default();
        self.on_timer_into(cfg, pdu, now, &mut f).step(&f)
    }

    /// [`Tx::on_timer`], the frame written into `out` ([`TxAction`]).
    pub fn on_timer_into(
        &mut self,
        cfg: &Config,
        pdu: &[u8],
        now: u64,
        out: &mut LlFrame,
    ) -> TxAction {
        match self.deadline {
            Some(d) if now >= d => {}
            _ => return TxAction::NONE,
        }
        self.deadline = None;
        match self.st {
            St::Idle => TxAction::NONE,
            St::Sending if !self.echo_pending => self.send_cf(cfg, pdu, now, out),
            _ => self.finish(Err(ECOMM)),
        }
    }

    /// Abandons a running transfer without a result (the socket closes or
    /// loses its device); the timer is cancelled.
    pub fn abort(&mut self) -> TxStep {
        self.st = St::Idle;
        self.echo_pending = false;
        TxStep {
            timer: self.timer(TimerCmd::Cancel),
            ..TxStep::NONE
        }
    }
}

#[cfg(test)]
// Tests start from the defaults and change what they exercise.
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::super::isotp::{
        LlOptions, Timeouts, CAN_ISOTP_SF_BROADCAST, ECHO_TIMEOUT_NS, FC_TIMEOUT_NS,
    };
    use super::*;

    const MS: u64 = 1_000_000;

    fn cfg() -> Config {
        let mut c = Config::default();
        c.frame_txtime = 0;
        c
    }

    #[test]
    fn single_frame_done_on_echo() {
        let c = cfg();
        let mut tx = Tx::new();
        let s = tx.start(&c, &[1, 2, 3], 10).unwrap();
        assert_eq!(s.frame.unwrap().payload(), &[3, 1, 2, 3]);
        assert!(s.wants_echo);
        assert_eq!(s.timer, TimerCmd::Arm(10 + ECHO_TIMEOUT_NS));
        assert_eq!(tx.start(&c, &[1], 11), Err(EAGAIN));
        let s = tx.on_echo(&c, &[1, 2, 3], 20);
        assert_eq!(
            (s.done, s.timer, s.frame),
            (Some(Ok(())), TimerCmd::Cancel, None)
        );
        assert!(tx.is_idle());
    }

    #[test]
    fn start_errors() {
        let mut c = cfg();
        let mut tx = Tx::new();
        assert_eq!(tx.start(&c, &[], 0), Err(EINVAL));
        c.opt.flags = CAN_ISOTP_SF_BROADCAST;
        assert_eq!(tx.start(&c, &[0; 8], 0), Err(EINVAL));
        assert!(tx.is_idle());
        assert!(tx.start(&c, &[0; 7], 0).is_ok());
    }

    #[test]
    fn echo_timeout_is_ecomm() {
        let c = cfg();
        let mut tx = Tx::new();
        tx.start(&c, &[1], 0).unwrap();
        // Stale expiry before the deadline: nothing.
        assert_eq!(tx.on_timer(&c, &[1], ECHO_TIMEOUT_NS - 1), TxStep::NONE);
        let s = tx.on_timer(&c, &[1], ECHO_TIMEOUT_NS);
        assert_eq!(s.done, Some(Err(ECOMM)));
        assert!(tx.is_idle());
        // A late echo changes nothing.
        assert_eq!(tx.on_echo(&c, &[1], ECHO_TIMEOUT_NS + 1), TxStep::NONE);
    }

    /// Other timeouts (rcan_isotp's test-only parameters): N_Bs and the
    /// echo wait run for them, not for mainline's 1 s and 2 s.
    #[test]
    fn configured_timeouts() {
        let mut c = cfg();
        c.timeouts = Timeouts::from_ms(15_000, 20_000);
        let pdu: Vec<u8> = (0..20u8).collect();
        let mut tx = Tx::new();
        let s = tx.start(&c, &pdu, 0).unwrap();
        assert_eq!(s.timer, TimerCmd::Arm(15_000 * MS));
        assert_eq!(tx.on_timer(&c, &pdu, 15_000 * MS - 1), TxStep::NONE);
        let s = tx.on_fc(&c, &[0x30, 0, 0], &pdu, 15_000 * MS - 1);
        assert_eq!(s.timer, TimerCmd::Arm(35_000 * MS - 1));
        assert_eq!(tx.on_timer(&c, &pdu, 35_000 * MS - 2), TxStep::NONE);
        let s = tx.on_timer(&c, &pdu, 35_000 * MS - 1);
        assert_eq!(s.done, Some(Err(ECOMM)));
        // SF: the echo wait.
        let s = tx.start(&c, &[1], 0).unwrap();
        assert_eq!(s.timer, TimerCmd::Arm(20_000 * MS));
        // The default is mainline's, and the parameters are clamped.
        assert_eq!(
            Timeouts::default(),
            Timeouts {
                fc_ns: FC_TIMEOUT_NS,
                echo_ns: ECHO_TIMEOUT_NS
            }
        );
        assert_eq!(Timeouts::from_ms(1000, 2000), Timeouts::default());
        assert_eq!(
            Timeouts::from_ms(0, u32::MAX),
            Timeouts {
                fc_ns: MS,
                echo_ns: 600_000 * MS
            }
        );
    }

    /// FF, FC(CTS, BS 2, STmin 5 ms), 2 CFs, wait FC, FC, last CF.
    #[test]
    fn blocks_and_stmin() {
        let c = cfg();
        let pdu: Vec<u8> = (0..23u8).collect();
        let mut tx = Tx::new();
        let s = tx.start(&c, &pdu, 0).unwrap();
        assert_eq!(s.frame.unwrap().payload(), &[0x10, 23, 0, 1, 2, 3, 4, 5]);
        assert!(!s.wants_echo);
        assert_eq!(s.timer, TimerCmd::Arm(FC_TIMEOUT_NS));
        // The FF's echo (not asked for) is ignored.
        assert_eq!(tx.on_echo(&c, &pdu, 1), TxStep::NONE);
        let s = tx.on_fc(&c, &[0x30, 2, 5], &pdu, MS);
        assert_eq!(s.frame.unwrap().payload(), &[0x21, 6, 7, 8, 9, 10, 11, 12]);
        assert_eq!(s.timer, TimerCmd::Arm(MS + ECHO_TIMEOUT_NS));
        // Echo: the gap of 5 ms starts.
        let s = tx.on_echo(&c, &pdu, 2 * MS);
        assert_eq!((s.frame, s.timer), (None, TimerCmd::Arm(7 * MS)));
        assert_eq!(tx.on_timer(&c, &pdu, 6 * MS), TxStep::NONE);
        let s = tx.on_timer(&c, &pdu, 7 * MS);
        assert_eq!(s.frame.unwrap().payload()[0], 0x22);
        // Block of 2 complete: wait for FC.
        let s = tx.on_echo(&c, &pdu, 8 * MS);
        assert_eq!(
            (s.frame, s.timer),
            (None, TimerCmd::Arm(8 * MS + FC_TIMEOUT_NS))
        );
        // An echo now is ignored; a wait frame extends the wait.
        assert_eq!(tx.on_echo(&c, &pdu, 9 * MS), TxStep::NONE);
        let s = tx.on_fc(&c, &[0x31, 0, 0], &pdu, 10 * MS);
        assert_eq!(s.timer, TimerCmd::Arm(10 * MS + FC_TIMEOUT_NS));
        // Second FC: its BS/STmin are ignored (not dynamic).
        let s = tx.on_fc(&c, &[0x30, 0, 0], &pdu, 11 * MS);
        let f = s.frame.unwrap();
        assert_eq!(f.payload(), &[0x23, 20, 21, 22]);
        let s = tx.on_echo(&c, &pdu, 12 * MS);
        assert_eq!(s.done, Some(Ok(())));
    }

    /// The socket's own flow control frame (its receiver, for the other
    /// direction, sends on the same identifier) comes back while a CF's
    /// echo is awaited: not that echo. Before, any own frame on the
    /// identifier was taken as it, and the next CF went out early (the
    /// STmin gap started from the FC's echo).
    #[test]
    fn own_fc_echo_is_not_the_cf_echo() {
        let c = cfg();
        let pdu: Vec<u8> = (0..23u8).collect();
        let mut tx = Tx::new();
        tx.start(&c, &pdu, 0).unwrap();
        // The FF's echo (not awaited) is no echo either.
        assert!(!tx.echo_matches(&[0x10, 23, 0, 1, 2, 3, 4, 5]));
        let s = tx.on_fc(&c, &[0x30, 0, 5], &pdu, MS);
        let cf = s.frame.unwrap();
        assert_eq!(cf.payload()[0], 0x21);
        // Our receiver's FC (continue, BS 4) echoed: ignored, still waiting.
        let fc = [0x30, 4, 0, 0, 0, 0, 0, 0];
        assert!(!tx.echo_matches(&fc));
        assert_eq!(tx.on_own_frame(&c, &fc, &pdu, 2 * MS), TxStep::NONE);
        // The CF's own echo: the 5 ms gap starts from it.
        assert!(tx.echo_matches(cf.payload()));
        let s = tx.on_own_frame(&c, cf.payload(), &pdu, 3 * MS);
        assert_eq!((s.frame, s.timer), (None, TimerCmd::Arm(8 * MS)));
        // Its late duplicate is no echo of the next CF.
        let s = tx.on_timer(&c, &pdu, 8 * MS);
        let cf2 = s.frame.unwrap();
        assert_eq!(cf2.payload()[0], 0x22);
        assert_eq!(tx.on_own_frame(&c, cf.payload(), &pdu, 9 * MS), TxStep::NONE);
        let s = tx.on_own_frame(&c, cf2.payload(), &pdu, 10 * MS);
        assert_eq!((s.frame, s.timer), (None, TimerCmd::Arm(15 * MS)));
    }

    /// A single frame's echo is matched too (short frames: the tag is the
    /// frame's whole payload).
    #[test]
    fn single_frame_echo_matched() {
        let c = cfg();
        let mut tx = Tx::new();
        let s = tx.start(&c, &[7], 0).unwrap();
        let sf = s.frame.unwrap();
        assert!(!tx.echo_matches(&[0x30, 0, 0]));
        assert!(!tx.echo_matches(&[]));
        let s = tx.on_own_frame(&c, sf.payload(), &[7], 1);
        assert_eq!(s.done, Some(Ok(())));
    }

    #[test]
    fn dynamic_fc_parameters() {
        let mut c = cfg();
        c.opt.flags = CAN_ISOTP_DYN_FC_PARMS;
        let pdu = [0u8; 30];
        let mut tx = Tx::new();
        tx.start(&c, &pdu, 0).unwrap();
        tx.on_fc(&c, &[0x30, 1, 0], &pdu, 0);
        // BS 1: wait for FC after each CF.
        tx.on_echo(&c, &pdu, 0);
        let s = tx.on_fc(&c, &[0x30, 0, 0xF5], &pdu, 0);
        assert!(s.frame.is_some());
        // New STmin 500 µs applies.
        let s = tx.on_echo(&c, &pdu, 0);
        assert_eq!(s.timer, TimerCmd::Arm(500_000));
    }

    #[test]
    fn fc_errors() {
        let c = cfg();
        let pdu = [0u8; 20];
        for (fc, err) in [
            (&[0x32u8, 0, 0][..], EMSGSIZE),
            (&[0x33, 0, 0][..], EBADMSG),
            (&[0x3F, 0, 0][..], EBADMSG),
            (&[0x30, 0][..], EBADMSG),
        ] {
            let mut tx = Tx::new();
            tx.start(&c, &pdu, 0).unwrap();
            let s = tx.on_fc(&c, fc, &pdu, 1);
            assert_eq!(s.done, Some(Err(err)), "{fc:x?}");
            assert_eq!(s.timer, TimerCmd::Cancel);
            assert!(tx.is_idle());
        }
        let mut tx = Tx::new();
        tx.start(&c, &pdu, 0).unwrap();
        assert_eq!(tx.on_timer(&c, &pdu, FC_TIMEOUT_NS).done, Some(Err(ECOMM)));
        // An FC while sending or idle is ignored.
        assert_eq!(tx.on_fc(&c, &[0x32, 0, 0], &pdu, 0), TxStep::NONE);
    }

    #[test]
    fn fc_padding_checked_when_asked() {
        use super::super::isotp::{
            CAN_ISOTP_CHK_PAD_DATA, CAN_ISOTP_CHK_PAD_LEN, CAN_ISOTP_RX_PADDING,
        };
        let mut c = cfg();
        c.opt.flags = CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN | CAN_ISOTP_CHK_PAD_DATA;
        c.opt.rxpad_content = 0x55;
        let pdu = [0u8; 20];
        for (fc, ok) in [
            (&[0x30u8, 0, 0, 0x55, 0x55, 0x55, 0x55, 0x55][..], true),
            (&[0x30, 0, 0, 0x55, 0x55, 0x55, 0x55, 0xCC][..], false),
            (&[0x30, 0, 0][..], false),
        ] {
            let mut tx = Tx::new();
            tx.start(&c, &pdu, 0).unwrap();
            let s = tx.on_fc(&c, fc, &pdu, 1);
            if ok {
                assert!(s.frame.is_some() && s.done.is_none());
            } else {
                assert_eq!(s.done, Some(Err(EBADMSG)), "{fc:x?}");
            }
        }
    }

    #[test]
    fn reserved_stmin_is_127ms_and_forced_stmin_wins() {
        let mut c = cfg();
        let pdu = [0u8; 30];
        let mut tx = Tx::new();
        tx.start(&c, &pdu, 0).unwrap();
        tx.on_fc(&c, &[0x30, 0, 0x80], &pdu, 0);
        assert_eq!(tx.on_echo(&c, &pdu, 0).timer, TimerCmd::Arm(127 * MS));
        c.opt.flags = CAN_ISOTP_FORCE_TXSTMIN;
        c.force_tx_stmin = 1234;
        c.frame_txtime = 1000;
        let mut tx = Tx::new();
        tx.start(&c, &pdu, 0).unwrap();
        tx.on_fc(&c, &[0x30, 0, 0x10], &pdu, 0);
        assert_eq!(tx.on_echo(&c, &pdu, 0).timer, TimerCmd::Arm(2234));
    }

    #[test]
    fn cf_broadcast_needs_no_fc() {
        let mut c = cfg();
        c.opt.flags = CAN_ISOTP_CF_BROADCAST;
        let pdu = [7u8; 20];
        let mut tx = Tx::new();
        let s = tx.start(&c, &pdu, 0).unwrap();
        assert!(s.wants_echo);
        let s = tx.on_echo(&c, &pdu, 1);
        assert_eq!(s.frame.unwrap().data[0], 0x21);
        let s = tx.on_echo(&c, &pdu, 2);
        assert_eq!(s.frame.unwrap().data[0], 0x22);
        assert_eq!(tx.on_echo(&c, &pdu, 3).done, Some(Ok(())));
    }

    #[test]
    fn fd_escape_and_wrong_pdu() {
        let mut c = cfg();
        c.ll = LlOptions {
            mtu: 72,
            tx_dl: 64,
            tx_flags: 0,
        };
        let pdu = vec![1u8; 5000];
        let mut tx = Tx::new();
        let s = tx.start(&c, &pdu, 0).unwrap();
        assert_eq!(
            &s.frame.unwrap().payload()[..6],
            &[0x10, 0, 0, 0, 0x13, 0x88]
        );
        // The caller hands a shorter buffer: EINVAL, no panic.
        let s = tx.on_fc(&c, &[0x30, 0, 0], &pdu[..10], 0);
        assert_eq!(s.done, Some(Err(EINVAL)));
    }

    #[test]
    fn abort_cancels() {
        let c = cfg();
        let mut tx = Tx::new();
        tx.start(&c, &[0; 100], 0).unwrap();
        assert_eq!(tx.abort().timer, TimerCmd::Cancel);
        assert!(tx.is_idle());
        assert_eq!(tx.deadline(), None);
        assert_eq!(tx.on_timer(&c, &[0; 100], u64::MAX), TxStep::NONE);
    }
}

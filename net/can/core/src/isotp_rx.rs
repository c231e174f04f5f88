// SPDX-License-Identifier: GPL-2.0
//! The ISO-TP receiver of one socket as a pure state machine over virtual
//! time: mainline's `isotp_rcv_sf`, `isotp_rcv_ff`, `isotp_rcv_cf`,
//! `isotp_send_fc` and its receive timer, rewritten.
//! Documentation/networking/rcan/isotp.rst, "Receiver".
//!
//! One [`Rx`] exists per socket. The PDU is reassembled into a buffer the
//! caller owns and passes to every event (the module's per-socket buffer
//! of `max_pdu_size` bytes); its length is the largest PDU accepted:
//! a first frame announcing more gets a flow control "overflow". Each
//! event returns an [`RxStep`]: at most one flow control frame to send,
//! what to do with the receive timer (absolute deadlines, see
//! [`TimerCmd`]), and a delivered PDU or an error. The caller serializes
//! all calls (the module holds the socket's receive lock); nothing here
//! sleeps or allocates. In the module every event runs in softirq
//! context (frame reception, hrtimer).

use super::isotp::{
    Config, TimerCmd, CAN_ISOTP_FORCE_RXSTMIN, CAN_ISOTP_LISTEN_MODE, EBADMSG, EILSEQ, ETIMEDOUT,
};
use super::isotp_pci::{
    copy_payload, pad_ok, parse_ff, parse_sf, write_fc, LlFrame, FS_CTS, FS_OVFLW, N_PCI_CF,
    N_PCI_FF, N_PCI_SF,
};

/// What the receiver reports to the socket.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum RxEvent {
    /// A whole PDU of this many bytes is in `buf[..n]`: queue it.
    Deliver(usize),
    /// The reception failed with this errno (`ETIMEDOUT`, `EILSEQ`,
    /// `EBADMSG`): report it as the socket's error.
    Error(i32),
}

/// What the caller does after a receiver event.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RxStep {
    /// A flow control frame to send now (with `tx_id`; no echo needed).
    pub frame: Option<LlFrame>,
    /// The receive timer.
    pub timer: TimerCmd,
    /// A delivered PDU or an error.
    pub event: Option<RxEvent>,
}

impl RxStep {
    const NONE: RxStep = RxStep {
        frame: None,
        timer: TimerCmd::Keep,
        event: None,
    };
}

/// What the caller does after [`Rx::on_frame_into`]: an [`RxStep`] whose
/// flow control frame the machine wrote into the caller's buffer (see
/// [`LlFrame`]) instead of returning it. The module uses it;
/// [`Rx::on_frame`] wraps it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RxAction {
    /// The caller's buffer holds a frame to send now ([`RxStep::frame`]).
    pub frame: bool,
    /// See [`RxStep::timer`].
    pub timer: TimerCmd,
    /// See [`RxStep::event`].
    pub event: Option<RxEvent>,
}

impl RxAction {
    const NONE: RxAction = RxAction {
        frame: false,
        timer: TimerCmd::Keep,
        event: None,
    };

    /// The by-value step, with the frame `f` the action wrote.
    pub fn step(&self, f: &LlFrame) -> RxStep {
        RxStep {
            frame: self.frame.then_some(*f),
            timer: self.timer,
            event: self.event,
        }
    }
}

/// The receiver of one socket; owned by the socket, protected by its
/// receive lock in the module.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Rx {
    /// Waiting for consecutive frames (mainline `ISOTP_WAIT_DATA`).
    active: bool,
    /// FF_DL of the running reception.
    len: usize,
    /// Bytes received so far.
    idx: usize,
    /// Expected sequence number of the next CF.
    sn: u8,
    /// CFs received since our last flow control frame.
    bs: u8,
    /// The sender's TX_DL (length of its FF).
    ll_dl: u8,
    /// Time of the last CF taken, for [`CAN_ISOTP_FORCE_RXSTMIN`]; 0
    /// after each FC we send.
    last_cf: u64,
    /// When the timer expires, if armed.
    deadline: Option<u64>,
}

impl Default for Rx {
    fn default() -> Self {
        Self::new()
    }
}

impl Rx {
    /// An idle receiver.
    pub const fn new() -> Self {
        Rx {
            active: false,
            len: 0,
            idx: 0,
            sn: 0,
            bs: 0,
            ll_dl: 0,
            last_cf: 0,
            deadline: None,
        }
    }

    /// Whether no multi-frame reception is running.
    pub fn is_idle(&self) -> bool {
        !self.active
    }

    /// Bytes of the running reception so far (0 when idle).
    pub fn received(&self) -> usize {
        if self.active {
            self.idx
        } else {
            0
        }
    }

    /// The timer's deadline, if armed.
    pub fn deadline(&self) -> Option<u64> {
        self.deadline
    }

    fn step(&mut self, frame: bool, timer: TimerCmd, event: Option<RxEvent>) -> RxAction {
        self.deadline = match timer {
            TimerCmd::Arm(at) => Some(at),
            TimerCmd::Cancel => None,
            TimerCmd::Keep => self.deadline,
        };
        RxAction {
            frame,
            timer,
            event,
        }
    }

    /// Our flow control frame with status `fs` into `out`; restarts the
    /// block count and the N_Cr timeout.
    fn send_fc(&mut self, cfg: &Config, fs: u8, now: u64, out: &mut LlFrame) -> RxAction {
        self.bs = 0;
        self.last_cf = 0;
        write_fc(cfg, fs, out);
        self.step(true, TimerCmd::Arm(now.saturating_add(cfg.timeouts.fc_ns)), None)
    }

    /// A single, first or consecutive frame for this socket arrived at
    /// `now` (`data`: the payload, address byte included, routed by
    /// [`super::isotp::route`]); `buf` is the reassembly buffer, the same
    /// one for every event. An SF or FF ends a running reception
    /// silently and starts anew; frames that do not fit the protocol are
    /// ignored (see isotp.rst for the list); padding is checked on SFs
    /// and on the last CF (`EBADMSG`), sequence numbers on every CF
    /// (`EILSEQ`).
    pub fn on_frame(&mut self, cfg: &Config, data: &[u8], buf: &mut [u8], now: u64) -> RxStep {
        let mut f = LlFrame::default();
        self.on_frame_into(cfg, data, buf, now, &mut f).step(&f)
    }

    /// [`Rx::on_frame`], the flow control frame written into `out`
    /// ([`RxAction`]).
    pub fn on_frame_into(
        &mut self,
        cfg: &Config,
        data: &[u8],
        buf: &mut [u8],
        now: u64,
        out: &mut LlFrame,
    ) -> RxAction {
        let Some(&pci) = data.get(cfg.ae()) else {
            return RxAction::NONE;
        };
        match pci & 0xF0 {
            N_PCI_SF => self.on_sf(cfg, data, buf),
            N_PCI_FF => self.on_ff(cfg, data, buf, now, out),
            N_PCI_CF => self.on_cf(cfg, data, buf, now, out),
            _ => RxAction::NONE,
        }
    }

    fn on_sf(&mut self, cfg: &Config, data: &[u8], buf: &mut [u8]) -> RxAction {
        self.active = false;
        let Some((pcilen, len)) = parse_sf(cfg, data) else {
            return self.step(false, TimerCmd::Cancel, None);
        };
        if !pad_ok(cfg, data, pcilen + len) {
            return self.step(false, TimerCmd::Cancel, Some(RxEvent::Error(EBADMSG)));
        }
        let Some(dst) = buf.get_mut(..len) else {
            return self.step(false, TimerCmd::Cancel, None);
        };
        copy_payload(dst, &data[pcilen..pcilen + len]);
        self.step(false, TimerCmd::Cancel, Some(RxEvent::Deliver(len)))
    }

    fn on_ff(
        &mut self,
        cfg: &Config,
        data: &[u8],
        buf: &mut [u8],
        now: u64,
        out: &mut LlFrame,
    ) -> RxAction {
        self.active = false;
        let Some(h) = parse_ff(cfg, data) else {
            return self.step(false, TimerCmd::Cancel, None);
        };
        let listen = cfg.has(CAN_ISOTP_LISTEN_MODE);
        let len = h.len as usize;
        if len > buf.len() {
            // Differs from mainline: a listener sends no overflow FC.
            if listen {
                return self.step(false, TimerCmd::Cancel, None);
            }
            write_fc(cfg, FS_OVFLW, out);
            return self.step(true, TimerCmd::Cancel, None);
        }
        // parse_ff() guarantees pcilen < ll_dl == data.len() and that
        // the FF carries fewer bytes than FF_DL.
        let head = &data[h.pcilen..];
        buf[..head.len()].copy_from_slice(head);
        self.idx = head.len();
        self.len = len;
        self.ll_dl = h.ll_dl;
        self.sn = 1;
        self.active = true;
        if listen {
            // As mainline: no FC, and no timeout until the first CF.
            return self.step(false, TimerCmd::Cancel, None);
        }
        self.send_fc(cfg, FS_CTS, now, out)
    }

    fn on_cf(
        &mut self,
        cfg: &Config,
        data: &[u8],
        buf: &mut [u8],
        now: u64,
        out: &mut LlFrame,
    ) -> RxAction {
        if !self.active {
            return RxAction::NONE;
        }
        if cfg.has(CAN_ISOTP_FORCE_RXSTMIN) {
            if now.saturating_sub(self.last_cf) < u64::from(cfg.force_rx_stmin) {
                return RxAction::NONE;
            }
            self.last_cf = now;
        }
        let ae = cfg.ae();
        let ll_dl = usize::from(self.ll_dl);
        let rest = self.len.saturating_sub(self.idx);
        // Differs from mainline: a CF of the wrong length is ignored
        // without stopping the N_Cr timer (mainline cancels it and the
        // reception hangs until the next SF or FF).
        if data.len() > ll_dl || (data.len() < ll_dl && rest > ll_dl - ae - 1) {
            return RxAction::NONE;
        }
        if data[ae] & 0x0F != self.sn {
            self.active = false;
            return self.step(false, TimerCmd::Cancel, Some(RxEvent::Error(EILSEQ)));
        }
        self.sn = (self.sn + 1) & 0x0F;
        let src = &data[ae + 1..];
        let n = src.len().min(rest);
        let Some(dst) = buf.get_mut(self.idx..self.idx + n) else {
            // The caller passed a shorter buffer than at the FF.
            self.active = false;
            return self.step(false, TimerCmd::Cancel, None);
        };
        copy_payload(dst, &src[..n]);
        self.idx += n;
        if self.idx >= self.len {
            self.active = false;
            if !pad_ok(cfg, data, ae + 1 + n) {
                return self.step(false, TimerCmd::Cancel, Some(RxEvent::Error(EBADMSG)));
            }
            return self.step(false, TimerCmd::Cancel, Some(RxEvent::Deliver(self.len)));
        }
        let bs = cfg.rxfc.bs;
        if bs == 0 || {
            self.bs = self.bs.wrapping_add(1);
            self.bs < bs
        } {
            return self.step(false, TimerCmd::Arm(now.saturating_add(cfg.timeouts.fc_ns)), None);
        }
        if cfg.has(CAN_ISOTP_LISTEN_MODE) {
            return self.step(false, TimerCmd::Cancel, None);
        }
        self.send_fc(cfg, FS_CTS, now, out)
    }

    /// The receive timer fired at `now`. Before the deadline (a stale
    /// expiry) or with none armed: ignored. Else a running reception
    /// ends with `ETIMEDOUT` (N_Cr).
    pub fn on_timer(&mut self, now: u64) -> RxStep {
        match self.deadline {
            Some(d) if now >= d => {}
            _ => return RxStep::NONE,
        }
        self.deadline = None;
        if !self.active {
            return RxStep::NONE;
        }
        self.active = false;
        RxStep {
            event: Some(RxEvent::Error(ETIMEDOUT)),
            ..RxStep::NONE
        }
    }

    /// Abandons a running reception silently (close, device gone).
    pub fn abort(&mut self) -> RxStep {
        self.active = false;
        self.step(false, TimerCmd::Cancel, None)
            .step(&LlFrame::default())
    }
}

#[cfg(test)]
// Tests start from the defaults and change what they exercise.
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::super::isotp::{
        LlOptions, Timeouts, CAN_ISOTP_CHK_PAD_DATA, CAN_ISOTP_CHK_PAD_LEN, CAN_ISOTP_EXTEND_ADDR,
        CAN_ISOTP_RX_PADDING, CAN_ISOTP_TX_PADDING, FC_TIMEOUT_NS,
    };
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn single_frame() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        let s = rx.on_frame(&c, &[0x03, 7, 8, 9], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Deliver(3)));
        assert_eq!(&buf[..3], &[7, 8, 9]);
        // Ignored: SF_DL 0 and a reserved N_PCI type.
        assert_eq!(rx.on_frame(&c, &[0x00, 7], &mut buf, 0).event, None);
        assert_eq!(rx.on_frame(&c, &[0x40, 7], &mut buf, 0), RxStep::NONE);
    }

    #[test]
    fn multi_frame_with_blocks() {
        let mut c = Config::default();
        c.rxfc.bs = 2;
        c.rxfc.stmin = 3;
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        let s = rx.on_frame(&c, &[0x10, 30, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        assert_eq!(s.frame.unwrap().payload(), &[0x30, 2, 3]);
        assert_eq!(s.timer, TimerCmd::Arm(FC_TIMEOUT_NS));
        let s = rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, MS);
        assert_eq!(
            (s.frame, s.timer),
            (None, TimerCmd::Arm(MS + FC_TIMEOUT_NS))
        );
        // Block of 2 complete: FC.
        let s = rx.on_frame(&c, &[0x22, 13, 14, 15, 16, 17, 18, 19], &mut buf, 2 * MS);
        assert_eq!(s.frame.unwrap().payload(), &[0x30, 2, 3]);
        assert_eq!(s.timer, TimerCmd::Arm(2 * MS + FC_TIMEOUT_NS));
        assert_eq!((rx.received(), s.event), (20, None));
    }

    #[test]
    fn reassembly_delivers_exact_bytes() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        rx.on_frame(&c, &[0x10, 15, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 0);
        // Last CF, short: allowed.
        let s = rx.on_frame(&c, &[0x22, 13, 14], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Deliver(15)));
        assert_eq!(s.timer, TimerCmd::Cancel);
        assert_eq!(&buf[..15], &(0..15).collect::<Vec<u8>>()[..]);
        assert!(rx.is_idle());
    }

    #[test]
    fn new_ff_or_sf_restarts_and_late_cf_is_ignored() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 0);
        // A new FF: the old reception is gone, sequence numbers restart.
        let s = rx.on_frame(&c, &[0x10, 9, 10, 11, 12, 13, 14, 15], &mut buf, 0);
        assert!(s.frame.is_some());
        let s = rx.on_frame(&c, &[0x21, 16, 17, 18], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Deliver(9)));
        assert_eq!(&buf[..9], &[10, 11, 12, 13, 14, 15, 16, 17, 18]);
        // A CF after completion: ignored.
        assert_eq!(rx.on_frame(&c, &[0x22, 1, 2], &mut buf, 0), RxStep::NONE);
        // An SF in the middle of a reception ends it silently.
        rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        let s = rx.on_frame(&c, &[0x01, 0xAA], &mut buf, 0);
        assert_eq!(
            (s.event, s.timer),
            (Some(RxEvent::Deliver(1)), TimerCmd::Cancel)
        );
        assert!(rx.is_idle());
        assert_eq!(
            rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 0),
            RxStep::NONE
        );
    }

    #[test]
    fn wrong_sequence_number_is_eilseq() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        let s = rx.on_frame(&c, &[0x22, 6, 7, 8, 9, 10, 11, 12], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Error(EILSEQ)));
        assert!(rx.is_idle());
    }

    #[test]
    fn sequence_numbers_wrap() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 200];
        rx.on_frame(&c, &[0x10, 150, 0, 0, 0, 0, 0, 0], &mut buf, 0);
        let mut got = None;
        for k in 1..=21u8 {
            let s = rx.on_frame(&c, &[0x20 | (k & 0xF), k, k, k, k, k, k, k], &mut buf, 0);
            got = s.event;
        }
        assert_eq!(got, Some(RxEvent::Deliver(150)));
        assert_eq!(buf[149], 21);
    }

    #[test]
    fn timeout_is_etimedout_and_stale_expiry_ignored() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 500 * MS);
        // The first deadline (1 s) was moved to 1.5 s.
        assert_eq!(rx.on_timer(FC_TIMEOUT_NS), RxStep::NONE);
        let s = rx.on_timer(500 * MS + FC_TIMEOUT_NS);
        assert_eq!(s.event, Some(RxEvent::Error(ETIMEDOUT)));
        assert!(rx.is_idle());
    }

    /// Another N_Cr (rcan_isotp's test-only parameter): the receiver
    /// waits that long after the FC and after each CF.
    #[test]
    fn configured_n_cr() {
        let mut c = Config::default();
        c.timeouts = Timeouts::from_ms(15_000, 2_000);
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        let s = rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        assert_eq!(s.timer, TimerCmd::Arm(15_000 * MS));
        let s = rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 2_000 * MS);
        assert_eq!(s.timer, TimerCmd::Arm(17_000 * MS));
        assert_eq!(rx.on_timer(15_000 * MS), RxStep::NONE);
        assert_eq!(rx.on_timer(17_000 * MS - 1), RxStep::NONE);
        let s = rx.on_timer(17_000 * MS);
        assert_eq!(s.event, Some(RxEvent::Error(ETIMEDOUT)));
    }

    #[test]
    fn overflow_fc() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 4095];
        let s = rx.on_frame(&c, &[0x10, 0, 0, 0, 0x10, 0, 0, 0], &mut buf, 0);
        assert_eq!(s.frame.unwrap().payload(), &[0x32, 0, 0]);
        assert!(rx.is_idle());
        let mut l = c;
        l.opt.flags = CAN_ISOTP_LISTEN_MODE;
        assert_eq!(
            rx.on_frame(&l, &[0x10, 0, 0, 0, 0x10, 0, 0, 0], &mut buf, 0)
                .frame,
            None
        );
    }

    #[test]
    fn listen_mode_sends_no_fc() {
        let mut c = Config::default();
        c.opt.flags = CAN_ISOTP_LISTEN_MODE;
        c.rxfc.bs = 1;
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        let s = rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        assert_eq!(s.frame, None);
        let s = rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 0);
        assert_eq!(s.frame, None);
        let s = rx.on_frame(&c, &[0x22, 13, 14, 15, 16, 17, 18, 19], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Deliver(20)));
    }

    #[test]
    fn bad_cf_length_keeps_the_timer() {
        let c = Config::default();
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        // A short CF that is not the last: ignored, timer untouched.
        assert_eq!(rx.on_frame(&c, &[0x21, 6, 7], &mut buf, 1), RxStep::NONE);
        assert_eq!(rx.deadline(), Some(FC_TIMEOUT_NS));
        assert_eq!(
            rx.on_timer(FC_TIMEOUT_NS).event,
            Some(RxEvent::Error(ETIMEDOUT))
        );
    }

    #[test]
    fn padding_errors_are_ebadmsg() {
        let mut c = Config::default();
        c.opt.flags = CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN | CAN_ISOTP_CHK_PAD_DATA;
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        let s = rx.on_frame(&c, &[0x02, 1, 2, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Deliver(2)));
        let s = rx.on_frame(&c, &[0x02, 1, 2, 0xCC, 0xCC, 0xCC, 0xCC, 0x00], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Error(EBADMSG)));
        let s = rx.on_frame(&c, &[0x02, 1, 2], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Error(EBADMSG)));
        // Last CF with bad padding.
        rx.on_frame(&c, &[0x10, 8, 0, 1, 2, 3, 4, 5], &mut buf, 0);
        let s = rx.on_frame(&c, &[0x21, 6, 7, 0xCC, 0xCC, 0xCC, 0xCC, 0xC0], &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Error(EBADMSG)));
    }

    #[test]
    fn force_rx_stmin_drops_close_cfs() {
        let mut c = Config::default();
        c.opt.flags = CAN_ISOTP_FORCE_RXSTMIN;
        c.force_rx_stmin = (2 * MS) as u32;
        let mut rx = Rx::new();
        let mut buf = [0u8; 100];
        rx.on_frame(&c, &[0x10, 20, 0, 1, 2, 3, 4, 5], &mut buf, 10 * MS);
        rx.on_frame(&c, &[0x21, 6, 7, 8, 9, 10, 11, 12], &mut buf, 11 * MS);
        // 1 ms later: dropped (sequence number not consumed).
        assert_eq!(
            rx.on_frame(&c, &[0x22, 0, 0, 0, 0, 0, 0, 0], &mut buf, 12 * MS),
            RxStep::NONE
        );
        let s = rx.on_frame(&c, &[0x22, 13, 14, 15, 16, 17, 18, 19], &mut buf, 13 * MS);
        assert_eq!(s.event, Some(RxEvent::Deliver(20)));
        assert_eq!(buf[13], 13);
    }

    #[test]
    fn fd_extended_addressing() {
        let mut c = Config::default();
        c.ll = LlOptions {
            mtu: 72,
            tx_dl: 64,
            tx_flags: 0,
        };
        c.opt.flags = CAN_ISOTP_EXTEND_ADDR | CAN_ISOTP_TX_PADDING;
        c.opt.ext_address = 0xA1;
        c.opt.rx_ext_address = 0xB2;
        let mut rx = Rx::new();
        let mut buf = [0u8; 200];
        let mut ff = [0u8; 64];
        ff[0] = 0xB2;
        ff[1] = 0x10;
        ff[2] = 100;
        let s = rx.on_frame(&c, &ff, &mut buf, 0);
        // Our FC carries our tx address, padded to 8.
        assert_eq!(
            s.frame.unwrap().payload(),
            &[0xA1, 0x30, 0, 0, 0xCC, 0xCC, 0xCC, 0xCC]
        );
        assert_eq!(rx.received(), 61);
        let mut cf = [0u8; 48];
        cf[0] = 0xB2;
        cf[1] = 0x21;
        let s = rx.on_frame(&c, &cf, &mut buf, 0);
        assert_eq!(s.event, Some(RxEvent::Deliver(100)));
    }
}

// SPDX-License-Identifier: GPL-2.0
//! One BCM receive operation (`RX_SETUP`): content filtering, change
//! detection, throttling, receive timeouts and remote-frame replies as a
//! pure state machine over virtual time. Mainline's `bcm_rx_setup`,
//! `bcm_rx_handler`, `bcm_rx_cmp_to_index`, `bcm_rx_update_and_send`,
//! `bcm_rx_timeout_handler` and `bcm_rx_thr_handler`, rewritten.
//!
//! One [`RxOp`] exists per (can_id, ifindex, CAN FD) key of a socket. The
//! filter frames (`filters`: for one frame its data is the relevance mask;
//! for several, frame 0's data is the mux mask and frames 1.. the mux
//! entries with their own masks) and the last received frame per entry
//! (`last`) live with the caller and are passed in. The caller serializes
//! all calls on one operation (mainline: `bcm_rx_update_lock`); effects go
//! to an [`RxOut`]. Nothing here sleeps or allocates; in the module
//! `setup` and `read` run in process context (`sendmsg`),
//! `frame_received` in NET_RX softirq (the receive callback) and the
//! timer expiries in hrtimer softirq context.
//!
//! Frames of both kinds are kept in the CAN FD layout ([`CanFdFrame`]: a
//! classic frame is its first 16 bytes, see [`super::bcm::widen`]); an
//! operation with [`CAN_FD_FRAME`] matches CAN FD frames only, one without
//! it classic frames only (mainline: `can_is_canfd_skb` /
//! `can_is_can_skb`).
//!
//! Change detection compares the data in 8-byte words under the entry's
//! mask, word by word for as many words as the received length starts
//! (`len` 1..=8: one word, 12: two, 64: eight; all 8 bytes of a word, also
//! those beyond the received length, as mainline's 64-bit compare does),
//! nothing for length 0; with [`RX_CHECK_DLC`] a changed length counts
//! too; the first frame after the setup (or after a timeout with
//! [`RX_ANNOUNCE_RESUME`]) always counts. The mux selector is the first
//! word only (also for CAN FD, as mainline).

use super::bcm::{
    data_word, BcmTimeval, MsgHead, CAN_FD_FRAME, RX_ANNOUNCE_RESUME, RX_CHANGED, RX_CHECK_DLC,
    RX_FILTER_ID, RX_NO_AUTOTIMER, RX_RTR_FRAME, RX_STATUS, RX_TIMEOUT, SETTIMER, STARTTIMER,
};
use super::frame::{AnyFrame, CanFdFrame};

/// The frame came from a socket on this host (`MSG_DONTROUTE` on the
/// `RX_CHANGED` message).
pub const TRAFFIC_LOCAL: u8 = 0x10;
/// The frame came from the socket of this operation (`MSG_CONFIRM`).
pub const TRAFFIC_OWN: u8 = 0x20;

/// The last frame received for one filter entry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RxSlot {
    /// The frame (a classic one in the CAN FD layout).
    pub frame: CanFdFrame,
    /// Something was received since the setup (or the last timeout with
    /// [`RX_ANNOUNCE_RESUME`]).
    pub recv: bool,
    /// A change is held back by the throttle and not yet reported.
    pub thr: bool,
    /// [`TRAFFIC_LOCAL`] | [`TRAFFIC_OWN`] of the frame.
    pub traffic: u8,
}

/// Where an [`RxOp`] sends its effects.
pub trait RxOut {
    /// Queue a message for user space: `RX_CHANGED` with `frame` (and its
    /// traffic flags), or `RX_TIMEOUT`/`RX_STATUS`; `rx_ifindex` is the
    /// interface `recvfrom` reports. For `RX_STATUS` the caller appends
    /// the operation's `head.nframes` filter frames itself (`frame` None).
    /// The frame is in the CAN FD layout; the message carries its first
    /// 16 bytes, or all 72 with [`CAN_FD_FRAME`].
    fn to_user(&mut self, head: &MsgHead, frame: Option<(&CanFdFrame, u8)>, rx_ifindex: i32);
    /// Transmit the reply of an [`RX_RTR_FRAME`] operation (filter frame 0)
    /// on `ifindex` (never 0: an operation on "any" interface does not
    /// reply).
    fn send_reply(&mut self, reply: &CanFdFrame, ifindex: i32);
    /// Arm the timeout timer at `at` (ns).
    fn arm_timeout(&mut self, at: u64);
    /// Cancel the timeout timer.
    fn cancel_timeout(&mut self);
    /// Arm the throttle timer at `at` (ns).
    fn arm_throttle(&mut self, at: u64);
    /// Cancel the throttle timer.
    fn cancel_throttle(&mut self);
}

/// State of one receive operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RxOp {
    /// Identifier (with flags) the operation receives.
    pub can_id: u32,
    /// Interface of the operation (0: any).
    pub ifindex: i32,
    /// Flags of the last setup.
    pub flags: u32,
    /// Always 0: mainline never stores an RX_SETUP's `count`, and
    /// reports 0 in every RX message.
    pub count: u32,
    /// Timeout interval as given.
    pub ival1: BcmTimeval,
    /// Throttle interval as given.
    pub ival2: BcmTimeval,
    /// Filter frames (0 with [`RX_FILTER_ID`], 1 plain, >1 mux).
    pub nframes: u32,
    /// Interface of the last received frame (for `recvfrom`).
    pub rx_ifindex: i32,
    /// With ifindex 0 and a timer in use: the interface the operation
    /// follows (the first that delivered a matching frame).
    pub if_detected: i32,
    /// When the last change was reported (throttle reference).
    pub lastmsg: Option<u64>,
    /// Expiry of the timeout timer, if armed.
    pub timeout_at: Option<u64>,
    /// Expiry of the throttle timer, if armed.
    pub throttle_at: Option<u64>,
}

impl RxOp {
    /// A new operation for a checked, normalized `RX_SETUP` head
    /// ([`super::bcm::rx_setup_head`], [`super::bcm::check_rx_setup`]) on
    /// `ifindex`; then call [`RxOp::setup`].
    pub fn new(head: &MsgHead, ifindex: i32) -> Self {
        Self {
            can_id: head.can_id,
            ifindex,
            flags: head.flags,
            count: 0,
            ival1: BcmTimeval::default(),
            ival2: BcmTimeval::default(),
            nframes: head.nframes,
            rx_ifindex: ifindex,
            if_detected: 0,
            lastmsg: None,
            timeout_at: None,
            throttle_at: None,
        }
    }

    /// Applies a normalized `RX_SETUP` at `now`, after the caller copied
    /// the head's frames into `filters` (and, for an update with frames,
    /// reset `last` to default: "nothing received"). [`SETTIMER`] takes
    /// both intervals, forgets the throttle reference and the detected
    /// interface, stops a timeout with `ival1` 0, and flushes held-back
    /// changes; [`STARTTIMER`] starts the timeout. [`RX_RTR_FRAME`]
    /// operations run no timers.
    pub fn setup(&mut self, head: &MsgHead, now: u64, last: &mut [RxSlot], out: &mut impl RxOut) {
        self.nframes = head.nframes;
        self.flags = head.flags;
        if head.flags & SETTIMER != 0 {
            self.ival1 = head.ival1;
            self.ival2 = head.ival2;
            self.lastmsg = None;
            self.if_detected = 0;
        }
        if self.flags & RX_RTR_FRAME != 0 {
            self.stop_throttle(out);
            self.stop_timeout(out);
            return;
        }
        if self.flags & SETTIMER != 0 {
            if self.ival1.to_ns() == 0 {
                self.stop_timeout(out);
            }
            self.stop_throttle(out);
            self.flush(last, out);
        }
        if self.flags & STARTTIMER != 0 && self.ival1.to_ns() != 0 {
            self.arm_timeout(now, out);
        }
    }

    /// A frame arrived at `now` on `rx_ifindex` (`traffic`:
    /// [`TRAFFIC_LOCAL`]/[`TRAFFIC_OWN`]); ignored unless it has this
    /// operation's identifier and kind (CAN FD with [`CAN_FD_FRAME`], else
    /// classic).
    #[allow(clippy::too_many_arguments)]
    pub fn frame_received(
        &mut self,
        rx: &AnyFrame,
        rx_ifindex: i32,
        traffic: u8,
        now: u64,
        filters: &[CanFdFrame],
        last: &mut [RxSlot],
        out: &mut impl RxOut,
    ) {
        if rx.can_id() != self.can_id || rx.is_fd() != (self.flags & CAN_FD_FRAME != 0) {
            return;
        }
        let rx = &match rx {
            AnyFrame::Classic(f) => super::bcm::widen(f),
            AnyFrame::Fd(f) => *f,
        };
        let timed = self.ival1.to_ns() != 0 || self.ival2.to_ns() != 0;
        if self.ifindex == 0 && self.flags & RX_RTR_FRAME == 0 && timed {
            if self.if_detected == 0 {
                self.if_detected = rx_ifindex;
            }
            if self.if_detected != rx_ifindex {
                return;
            }
        }
        self.stop_timeout(out);
        if self.flags & RX_RTR_FRAME != 0 {
            // Mainline sends the reply on the operation's interface; an
            // operation on "any" interface (0) has none and stays silent.
            if let (Some(reply), true) = (filters.first(), self.ifindex != 0) {
                out.send_reply(reply, self.ifindex);
            }
            return;
        }
        self.rx_ifindex = rx_ifindex;
        if self.flags & RX_FILTER_ID != 0 {
            self.update_and_send(0, rx, traffic, now, last, out);
        } else if self.nframes == 1 {
            self.compare(0, rx, traffic, now, filters, last, out);
        } else if self.nframes > 1 {
            let mux = filters.first().map_or(0, |f| data_word(f, 0));
            let got = data_word(rx, 0);
            let n = (self.nframes as usize).min(filters.len());
            if let Some(i) = (1..n).find(|&i| mux & got == mux & data_word(&filters[i], 0)) {
                self.compare(i, rx, traffic, now, filters, last, out);
            }
        }
        if self.flags & RX_NO_AUTOTIMER == 0 && self.ival1.to_ns() != 0 {
            self.arm_timeout(now, out);
        }
    }

    /// The timeout timer expired: `RX_TIMEOUT`, and with
    /// [`RX_ANNOUNCE_RESUME`] "nothing received" again. Not re-armed: the
    /// next frame re-arms it.
    pub fn timeout_expired(&mut self, last: &mut [RxSlot], out: &mut impl RxOut) {
        self.timeout_at = None;
        if self.flags & RX_ANNOUNCE_RESUME != 0 {
            let n = (self.nframes as usize).min(last.len());
            last[..n].fill(RxSlot::default());
        }
        out.to_user(&self.head(RX_TIMEOUT, 0), None, self.rx_ifindex);
    }

    /// The throttle timer expired at `now`: report the held-back changes;
    /// if there were any, the throttle runs for another `ival2` (forwarded
    /// past `now`), else it ends and the next change is reported at once.
    pub fn throttle_expired(&mut self, now: u64, last: &mut [RxSlot], out: &mut impl RxOut) {
        let prev = self.throttle_at.take().unwrap_or(now);
        let ival2 = self.ival2.to_ns();
        if self.flush(last, out) > 0 && ival2 != 0 {
            let periods = now.saturating_sub(prev) / ival2 + 1;
            let at = prev.saturating_add(periods.saturating_mul(ival2));
            self.throttle_at = Some(at);
            out.arm_throttle(at);
        } else {
            self.lastmsg = None;
        }
    }

    /// The `RX_STATUS` reply to `RX_READ` (the caller appends the filters).
    pub fn read(&self, out: &mut impl RxOut) {
        out.to_user(&self.head(RX_STATUS, self.nframes), None, self.rx_ifindex);
    }

    fn head(&self, opcode: u32, nframes: u32) -> MsgHead {
        MsgHead {
            opcode,
            flags: self.flags,
            count: self.count,
            ival1: self.ival1,
            ival2: self.ival2,
            can_id: self.can_id,
            nframes,
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn compare(
        &mut self,
        i: usize,
        rx: &CanFdFrame,
        traffic: u8,
        now: u64,
        filters: &[CanFdFrame],
        last: &mut [RxSlot],
        out: &mut impl RxOut,
    ) {
        let Some(slot) = last.get(i) else { return };
        let filter = filters.get(i);
        // Mainline: for (i = 0; i < len; i += 8) compare word i / 8.
        let words = usize::from(rx.len).min(rx.data.len()).div_ceil(8);
        let differs = (0..words).any(|w| {
            let mask = filter.map_or(0, |f| data_word(f, w));
            mask & data_word(rx, w) != mask & data_word(&slot.frame, w)
        });
        let changed =
            !slot.recv || differs || (self.flags & RX_CHECK_DLC != 0 && rx.len != slot.frame.len);
        if changed {
            self.update_and_send(i, rx, traffic, now, last, out);
        }
    }

    fn update_and_send(
        &mut self,
        i: usize,
        rx: &CanFdFrame,
        traffic: u8,
        now: u64,
        last: &mut [RxSlot],
        out: &mut impl RxOut,
    ) {
        let Some(slot) = last.get_mut(i) else { return };
        *slot = RxSlot {
            frame: *rx,
            recv: true,
            thr: true,
            traffic,
        };
        let ival2 = self.ival2.to_ns();
        if ival2 == 0 {
            self.changed(i, last, out);
            return;
        }
        if self.throttle_at.is_some() {
            return;
        }
        if let Some(lastmsg) = self.lastmsg {
            // Mainline compares in whole microseconds.
            if now.saturating_sub(lastmsg) / 1000 < ival2 / 1000 {
                let at = lastmsg + ival2;
                self.throttle_at = Some(at);
                out.arm_throttle(at);
                return;
            }
        }
        self.changed(i, last, out);
        self.lastmsg = Some(now);
    }

    fn changed(&self, i: usize, last: &mut [RxSlot], out: &mut impl RxOut) {
        let slot = &mut last[i];
        slot.thr = false;
        out.to_user(
            &self.head(RX_CHANGED, 1),
            Some((&slot.frame, slot.traffic)),
            self.rx_ifindex,
        );
    }

    /// Reports every held-back change (mux entries 1.., else entry 0);
    /// returns how many.
    fn flush(&self, last: &mut [RxSlot], out: &mut impl RxOut) -> usize {
        let range = if self.nframes > 1 {
            1..(self.nframes as usize).min(last.len())
        } else {
            0..last.len().min(1)
        };
        let mut n = 0;
        for i in range {
            if last[i].thr {
                self.changed(i, last, out);
                n += 1;
            }
        }
        n
    }

    fn arm_timeout(&mut self, now: u64, out: &mut impl RxOut) {
        let at = now.saturating_add(self.ival1.to_ns());
        self.timeout_at = Some(at);
        out.arm_timeout(at);
    }

    fn stop_timeout(&mut self, out: &mut impl RxOut) {
        if self.timeout_at.take().is_some() {
            out.cancel_timeout();
        }
    }

    fn stop_throttle(&mut self, out: &mut impl RxOut) {
        if self.throttle_at.take().is_some() {
            out.cancel_throttle();
        }
    }
}

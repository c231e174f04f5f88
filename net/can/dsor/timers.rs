// SPDX-License-Identifier: GPL-2.0

//! Sending frames and running the protocol timers of `rcan_dsor`: one
//! soft hrtimer, [`TIMER`] ([`Tick`]), kicked to "now" whenever frames are
//! queued on the engine outside a drainer and otherwise armed for the
//! earliest protocol deadline (or earlier: it is started again only when
//! a deadline comes before the expiry it is armed for, not once per
//! frame; a run that finds nothing due re-arms it for the next one).
//! [`drain_locked`] takes the engine's queued frames one at a time under
//! [`ENGINE`] and sends each without it, from the timer
//! (HRTIMER_SOFTIRQ) or from the receive callback (NET_RX softirq); at
//! most one drainer runs at a time (`Engine::draining`, under ENGINE), so
//! frames leave in queue order.

#![forbid(unsafe_code)]

use core::sync::atomic::{AtomicBool, Ordering};
use kernel::alloc::KBox;
use kernel::prelude::*;

use crate::engine::{now_ms, Engine, ENGINE, WAITQ};
use crate::glue;
use crate::glue::hrtimer::{ktime_get_mono_ns, HrTimer, HrTimerCallback};
use crate::glue::lock::BhSpinGuard;
use crate::glue::net::Net;
use crate::glue::netdev::{DevRef, NetDev};
use crate::glue::neterr;
use crate::rcan_api;
use crate::rcan_core::arb::{CAN_EFF_FLAG, CAN_EFF_MASK};
use crate::rcan_core::dsor_wire::FdFrame;
use crate::rcan_core::frame::{CanFdFrame, CanFrame, CANFD_FDF};

/// Frames one run of [`Tick`] sends at most before it re-arms itself for
/// "now" and returns, so that one long message (which, with the direct
/// echo, is acked within the same run: the queue then holds one frame at a
/// time) does not hold the softirq for its whole length. About the 2 ms
/// the kernel gives one softirq pass at ~2 us per frame (~8 ms under TCG).
const FRAMES_PER_RUN: usize = 1024;

/// Set by module exit: the timer neither sends nor re-arms.
pub(crate) static STOPPING: AtomicBool = AtomicBool::new(false);

/// The soft hrtimer that sends queued frames and runs protocol timers.
/// Started only under ENGINE, through `Engine::arm` and
/// `Engine::arm_for_deadline`, which remember what it is armed for.
pub(crate) struct Tick;

pub(crate) static TIMER: HrTimer<Tick> = HrTimer::new();

impl HrTimerCallback for Tick {
    type State = ();

    /// HRTIMER_SOFTIRQ. Runs the protocol timers, then drains the queue
    /// unless another drainer (a receive callback on another CPU) is at
    /// it; that one re-arms the timer when it is done.
    fn run(_timer: &'static HrTimer<Self>, _state: &mut ()) {
        let mut g = ENGINE.lock();
        let Some(e) = g.as_mut() else { return };
        // This run answers the last start: from here on the engine does
        // not know the timer to be armed (`Engine::timer_at`).
        e.timer_at = None;
        if STOPPING.load(Ordering::Relaxed) {
            return;
        }
        let before = e.stats.tx_ok + e.stats.tx_failed;
        e.on_timer(now_ms());
        let wake = e.stats.tx_ok + e.stats.tx_failed != before;
        drain_locked(g, wake, None);
    }
}

/// Sends the queued frames; `g` is ENGINE, held. Softirq context
/// (HRTIMER_SOFTIRQ or NET_RX).
///
/// Becomes the drainer if nobody is (`draining`), else returns at once:
/// the running drainer takes what was queued. Takes the frames from the
/// queue one at a time under ENGINE and sends each without it (on one
/// device reference for the whole run); when the queue is empty, clears
/// `draining` and arms the timer for the next deadline in the same
/// critical section (unless it is armed no later already), so that a
/// frame queued concurrently (also under ENGINE) is never left unsent.
/// After [`FRAMES_PER_RUN`] frames it arms the timer for "now" instead.
/// With `wake`, wakes [`WAITQ`] once ENGINE is dropped. `dev`, if given
/// (the receive callback lends the device the frame came in on, valid
/// for the callback: no reference taken and dropped per frame), is one
/// the caller found to bear the configured name (`Config::ifname`) while
/// holding `g`, so the first frame goes out on it unchecked (the name
/// can change only after `g` is dropped); later frames use it while its
/// name is still the configured one (else the device is looked up by
/// name, as without `dev`, and that reference kept for the run).
///
/// One frame per lock round, not a batch: the queue holds one frame at a
/// time in the common case (stop-and-wait; the receive callback drains
/// the one answer it queued), and a batch array set up per round (16
/// `Option<FdFrame>`, zeroed, then copied into) cost more than the lock
/// rounds it saved.
pub(crate) fn drain_locked(
    mut g: BhSpinGuard<Option<KBox<Engine>>>,
    mut wake: bool,
    mut dev: Option<&NetDev>,
) {
    match g.as_mut() {
        Some(e) if !e.draining && !STOPPING.load(Ordering::Relaxed) => e.draining = true,
        _ => {
            // Gone, stopping, or another drainer sends what was queued
            // and arms the timer when it finds the queue empty.
            drop(g);
            if wake {
                WAITQ.wake_all();
            }
            return;
        }
    }
    let mut held: Option<DevRef> = None;
    // `dev`'s name was compared with `ifname` under `g` (by the caller).
    let mut dev_checked = dev.is_some();
    let mut sent = 0;
    loop {
        let frame;
        let ifname;
        {
            let Some(e) = g.as_mut() else { break };
            if STOPPING.load(Ordering::Relaxed) {
                break;
            }
            if sent >= FRAMES_PER_RUN {
                e.draining = false;
                e.arm(ktime_get_mono_ns());
                break;
            }
            let Some(f) = e.pop_out() else {
                e.draining = false;
                e.arm_after_drain();
                break;
            };
            frame = f;
            ifname = e.cfg.ifname;
        }
        drop(g);
        if wake {
            WAITQ.wake_all();
            wake = false;
        }
        sent += 1;
        if !core::mem::take(&mut dev_checked)
            && dev.is_some_and(|d| d.name().as_bytes() != ifname.bytes())
        {
            dev = None;
        }
        if dev.is_none()
            && held
                .as_ref()
                .is_none_or(|d| d.name().as_bytes() != ifname.bytes())
        {
            held = DevRef::by_name(Net::init(), ifname.as_cstr());
        }
        let failed = match dev.or(held.as_deref()) {
            Some(d) => send_frame(d, &frame).is_err(),
            None => true,
        };
        g = ENGINE.lock();
        if failed {
            if let Some(e) = g.as_mut() {
                e.stats.send_errors += 1;
            }
        }
    }
    drop(g);
    if wake {
        WAITQ.wake_all();
    }
}

/// Sends `f` as a classic frame, or as a CAN FD frame (FDF set, BRS and
/// ESI clear) if it is one (an FD header or FD body); on an interface no
/// longer in FD mode pf_can refuses the latter (a send error, the
/// protocol retransmits until the transfer fails).
fn send_frame(dev: &NetDev, f: &FdFrame) -> Result {
    if !dev.is_can() || !dev.is_up() {
        return Err(neterr::ENETDOWN());
    }
    let can_id = (f.id & CAN_EFF_MASK) | CAN_EFF_FLAG;
    // The frame's image is built on the stack and copied into the skb
    // once (no `AnyFrame` in between).
    let skb = if f.fdf {
        let mut ff = CanFdFrame {
            can_id,
            len: f.len,
            flags: CANFD_FDF,
            ..CanFdFrame::default()
        };
        let n = usize::from(f.len).min(ff.data.len());
        ff.data[..n].copy_from_slice(&f.data[..n]);
        glue::can::skb::alloc_image(dev, &ff.to_bytes(), glue::GFP_ATOMIC)
    } else {
        let mut cf = CanFrame {
            can_id,
            len: f.len,
            ..CanFrame::default()
        };
        let n = usize::from(f.len.min(8));
        cf.data[..n].copy_from_slice(&f.data[..n]);
        glue::can::skb::alloc_image(dev, &cf.to_bytes(), glue::GFP_ATOMIC)
    }
    .ok_or(neterr::ENOBUFS())?;
    // Looped back, so that a node can talk to itself over canloop and
    // local CAN_RAW sockets see DSOR traffic.
    rcan_api::send(skb, dev, true)
}

// SPDX-License-Identifier: GPL-2.0

//! Sending frames and running the protocol timers of `rcan_dsor`: one
//! soft hrtimer, [`TIMER`] ([`Tick`]), kicked to "now" whenever frames are
//! queued on the engine and otherwise armed for the earliest protocol
//! deadline. [`drain`] takes the engine's queued frames in batches under
//! [`ENGINE`] and sends them without it, from the timer
//! (HRTIMER_SOFTIRQ) or from the receive callback (NET_RX softirq); at
//! most one drainer runs at a time (`Engine::draining`, under ENGINE), so
//! frames leave in queue order.

#![forbid(unsafe_code)]

use core::sync::atomic::{AtomicBool, Ordering};
use kernel::prelude::*;

use crate::engine::{now_ms, ENGINE, WAITQ};
use crate::glue;
use crate::glue::hrtimer::{ktime_get_mono_ns, HrTimer, HrTimerCallback};
use crate::glue::net::Net;
use crate::glue::netdev::DevRef;
use crate::glue::neterr;
use crate::rcan_api;
use crate::rcan_core::arb::{CAN_EFF_FLAG, CAN_EFF_MASK};
use crate::rcan_core::dsor_wire::FdFrame;
use crate::rcan_core::frame::{AnyFrame, CanFdFrame, CanFrame, CANFD_FDF};

/// Frames sent per batch (taken from the queue under the lock).
const BATCH: usize = 16;
/// Frames one run of [`Tick`] sends at most before it re-arms itself for
/// "now" and returns, so that one long message (which, with the direct
/// echo, is acked within the same run: the queue then holds one frame at a
/// time) does not hold the softirq for its whole length. About the 2 ms
/// the kernel gives one softirq pass at ~2 us per frame (~8 ms under TCG).
const FRAMES_PER_RUN: usize = 1024;

/// Set by module exit: the timer neither sends nor re-arms.
pub(crate) static STOPPING: AtomicBool = AtomicBool::new(false);

/// Kicks the sender timer. Call with ENGINE held (so that a kick is never
/// overwritten by an older re-arm, see [`Tick`]).
pub(crate) fn kick() {
    TIMER.start(ktime_get_mono_ns());
}

/// The soft hrtimer that sends queued frames and runs protocol timers.
pub(crate) struct Tick;

pub(crate) static TIMER: HrTimer<Tick> = HrTimer::new();

impl HrTimerCallback for Tick {
    type State = ();

    /// HRTIMER_SOFTIRQ. Runs the protocol timers, then drains the queue
    /// unless another drainer (a receive callback on another CPU) is at
    /// it; that one re-arms the timer when it is done.
    fn run(_timer: &'static HrTimer<Self>, _state: &mut ()) {
        drain(true, None);
    }
}

/// Sends the queued frames. Softirq context (HRTIMER_SOFTIRQ or NET_RX).
///
/// With `timers`, first runs the protocol timers. Becomes the drainer if
/// nobody is (`draining`), else returns at once: the running drainer takes
/// what was queued. Takes frames from the queue in batches under ENGINE
/// and sends them without it (on one device reference for the whole run);
/// when the queue is empty, clears `draining` and re-arms the timer for
/// the next deadline in the same critical section, so that a frame queued
/// concurrently (also under ENGINE) is never left unsent. After
/// [`FRAMES_PER_RUN`] frames it re-arms for "now" instead. `dev`, if
/// given, is used as the DSOR interface if its name is still the
/// configured one (else the device is looked up by name, as without).
pub(crate) fn drain(timers: bool, mut dev: Option<DevRef>) {
    let mut first = true;
    let mut wake = false;
    let mut sent = 0;
    loop {
        if wake {
            WAITQ.wake_all();
            wake = false;
        }
        let mut batch: [Option<FdFrame>; BATCH] = Default::default();
        let mut n = 0;
        let ifname;
        {
            let mut g = ENGINE.lock();
            let Some(e) = g.as_mut() else { return };
            if STOPPING.load(Ordering::Relaxed) {
                return;
            }
            if first {
                first = false;
                if timers {
                    let before = e.stats.tx_ok + e.stats.tx_failed;
                    e.on_timer(now_ms());
                    wake = e.stats.tx_ok + e.stats.tx_failed != before;
                }
                if e.draining {
                    // The running drainer sends what on_timer queued and
                    // re-arms the timer when it finds the queue empty.
                    drop(g);
                    if wake {
                        WAITQ.wake_all();
                    }
                    return;
                }
                e.draining = true;
            }
            if sent >= FRAMES_PER_RUN {
                e.draining = false;
                kick();
                drop(g);
                if wake {
                    WAITQ.wake_all();
                }
                return;
            }
            while n < BATCH {
                match e.pop_out() {
                    Some(f) => {
                        batch[n] = Some(f);
                        n += 1;
                    }
                    None => break,
                }
            }
            ifname = e.cfg.ifname;
            if dev
                .as_ref()
                .is_some_and(|d| d.name().as_bytes() != ifname.bytes())
            {
                dev = None;
            }
            if n == 0 {
                e.draining = false;
                if let Some(d) = e.next_deadline() {
                    TIMER.start((d as i64).saturating_mul(1_000_000));
                }
                drop(g);
                if wake {
                    WAITQ.wake_all();
                }
                return;
            }
        }
        sent += n;
        if dev.is_none() {
            dev = DevRef::by_name(Net::init(), ifname.as_cstr());
        }
        let errors = match &dev {
            Some(d) => send_batch(d, &batch[..n]),
            None => n as u64,
        };
        if errors != 0 {
            if let Some(e) = ENGINE.lock().as_mut() {
                e.stats.send_errors += errors;
            }
        }
    }
}

/// Sends frames on the DSOR interface; returns how many failed. Softirq.
fn send_batch(dev: &DevRef, frames: &[Option<FdFrame>]) -> u64 {
    let mut errors = 0;
    for f in frames.iter().flatten() {
        if send_frame(dev, f).is_err() {
            errors += 1;
        }
    }
    errors
}

/// Sends `f` as a classic frame, or as a CAN FD frame (FDF set, BRS and
/// ESI clear) if it is one (an FD header or FD body); on an interface no
/// longer in FD mode pf_can refuses the latter (a send error, the
/// protocol retransmits until the transfer fails).
fn send_frame(dev: &DevRef, f: &FdFrame) -> Result {
    if !dev.is_can() || !dev.is_up() {
        return Err(neterr::ENETDOWN());
    }
    let can_id = (f.id & CAN_EFF_MASK) | CAN_EFF_FLAG;
    let frame = if f.fdf {
        let mut ff = CanFdFrame {
            can_id,
            len: f.len,
            flags: CANFD_FDF,
            ..CanFdFrame::default()
        };
        let n = usize::from(f.len).min(ff.data.len());
        ff.data[..n].copy_from_slice(&f.data[..n]);
        AnyFrame::Fd(ff)
    } else {
        let mut cf = CanFrame {
            can_id,
            len: f.len,
            ..CanFrame::default()
        };
        let n = usize::from(f.len.min(8));
        cf.data[..n].copy_from_slice(&f.data[..n]);
        AnyFrame::Classic(cf)
    };
    let skb = glue::can::skb::alloc_frame(dev, &frame, glue::GFP_ATOMIC).ok_or(neterr::ENOBUFS())?;
    // Looped back, so that a node can talk to itself over canloop and
    // local CAN_RAW sockets see DSOR traffic.
    rcan_api::send(skb, dev, true)
}

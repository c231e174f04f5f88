// SPDX-License-Identifier: GPL-2.0

//! The 1 Hz time-frame ticker of `rcan_time` and `rcan_rtime` (thesis
//! 5.3.3, `dsor/time.c` and `dsor/rtime.c`). Both modules compile this
//! file in (`mod ticker;`), so each has its own copy of the statics below.
//!
//! Two timers: [`TICK`], absolute on `CLOCK_REALTIME`, fires at each whole
//! second of Linux time and sends the time frame (DSOR wire specification,
//! "Time frame") if the service's [`Policy`] says so; [`WATCH`], absolute
//! on `CLOCK_MONOTONIC`, fires `WATCHDOG_SLACK_NS` after `TICK` should
//! have and re-arms `TICK` if a backward clock step left it waiting for a
//! far-away second. What each does is computed by `rcan_core::timesvc`
//! (`on_timer`, `on_watchdog`, `Takeover`); this file reads the clocks,
//! arms the timers and sends.
//!
//! Contexts and shared items:
//!
//! * `VEHICLE`, `TIMEOUT_MS`, `DEV`: the module parameters, set by the C
//!   parameter callbacks (process context, kernel parameter lock;
//!   `vehicle` and `dev` only while loading, `timeout_ms` also later via
//!   sysfs), read by module init, the timer callbacks and the receiver.
//!   Atomics, no lock.
//! * `TICK`, `WATCH`: callbacks in `HRTIMER_SOFTIRQ` softirq, possibly at
//!   the same time on two CPUs; each may re-arm both timers (the hrtimer
//!   core serialises starts with its base lock). `TICK`'s callback alone
//!   owns [`TickState`]; it never runs concurrently with itself.
//! * `LAST_FOREIGN`: `CLOCK_MONOTONIC` arrival time of the newest time
//!   frame from another source. Written by `rcan_rtime`'s receiver (NET_RX
//!   softirq, `fetch_max`), read by `TICK`'s callback. An atomic.
//! * `STOPPING`: set by module exit; a callback that sees it neither sends
//!   nor re-arms. The counters (`SENT`, `SKIPPED`, `MISSED`, `STEPS_BACK`,
//!   `TAKEOVERS`) are atomics, written by the timer callbacks and read by
//!   module exit (process context) after [`stop`].
//! * `OWN_ECHO`: the data bytes of the last frame this service sent, until
//!   its echo comes back (0: none pending). Written by `TICK`'s callback
//!   before each send, cleared by the receiver that recognises the echo
//!   ([`take_own_echo`], NET_RX softirq). An atomic.
//!
//! Sending: the device is looked up by name at every send
//! (`dev_get_by_name`), so the service survives the device going down and
//! up, and even being unregistered and registered again; a second in which
//! the device is missing or down is skipped and counted, with one log line
//! per change of that state.
//!
//! Late callbacks: `TICK`'s callback names the second that contains now.
//! A callback that runs after the next boundary (the guest's CPUs stalled,
//! a long softirq) therefore skips the seconds in between; `on_timer`
//! counts them (`TimerFire::missed`) and, if the service sends at that
//! boundary, they are added to `MISSED`, reported at module exit.

#![forbid(unsafe_code)]
// Shared by two modules, each of which uses only part of it.
#![allow(dead_code)]

use core::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, AtomicU64, Ordering};
use kernel::prelude::*;
use kernel::str::CStr;

use crate::glue::can::skb::alloc_frame;
use crate::glue::module::ModuleScope;
use crate::glue::hrtimer::{
    ktime_get_mono_ns, ktime_get_real_ns, ClockId, HrTimer, HrTimerCallback, HrTimerMode,
};
use crate::glue::net::Net;
use crate::glue::netdev::DevRef;
use crate::rcan_api;
use crate::rcan_core::frame::AnyFrame;
use crate::rcan_core::timesvc::{
    self, Decision, Takeover, TimeFrame, DEFAULT_TIMEOUT_MS, DEFAULT_VEHICLE, IFNAME_MAX,
    SOURCE_RTIME, SOURCE_TIME,
};

/// Parameter numbers shared with the C file (`ticker_params.c`).
const PARAM_VEHICLE: u32 = 0;
const PARAM_TIMEOUT_MS: u32 = 1;

static VEHICLE: AtomicU32 = AtomicU32::new(DEFAULT_VEHICLE);
static TIMEOUT_MS: AtomicU32 = AtomicU32::new(DEFAULT_TIMEOUT_MS);
/// The `dev` parameter: 16 NUL-padded bytes in two words, default "can0".
static DEV: [AtomicU64; 2] = [
    AtomicU64::new(u64::from_le_bytes(*b"can0\0\0\0\0")),
    AtomicU64::new(0),
];

/// "No foreign frame yet."
const NEVER: i64 = i64::MIN;
static LAST_FOREIGN: AtomicI64 = AtomicI64::new(NEVER);
static STOPPING: AtomicBool = AtomicBool::new(false);
/// See the module documentation. A time frame's data is never all zero
/// (the source byte of `rcan_rtime`'s frames is 2), so 0 means none.
static OWN_ECHO: AtomicU64 = AtomicU64::new(0);

/// Whether `data`, the payload of a time frame with no sending socket
/// received on the service's device, is the echo of the frame this
/// service sent last; if so, that echo is consumed, so each frame sent
/// excuses exactly one received frame. NET_RX softirq.
///
/// Echoes are marked like frames from the bus (PACKET_BROADCAST, as on
/// mainline), so the service recognises its own by content: the frame it
/// sent names its second and its source byte. A frame from another node
/// that is identical (another `rcan_rtime` on the bus, same second) and
/// arrives before our echo is taken for ours; our echo then counts as the
/// foreign frame, so the foreign frame is still counted once. Only if our
/// echo is lost (a frame never sent, canloop's `droprate`) can one
/// identical foreign frame in that same second go uncounted.
pub(crate) fn take_own_echo(data: &[u8; 8]) -> bool {
    let v = u64::from_ne_bytes(*data);
    v != 0
        && OWN_ECHO
            .compare_exchange(v, 0, Ordering::AcqRel, Ordering::Relaxed)
            .is_ok()
}

static SENT: AtomicU64 = AtomicU64::new(0);
/// Seconds whose frame was not sent: device missing or down, send failed.
static SKIPPED: AtomicU64 = AtomicU64::new(0);
/// Seconds no frame named because `TICK`'s callback ran after the next
/// boundary (`TimerFire::missed`), counted when the service sends.
static MISSED: AtomicU64 = AtomicU64::new(0);
static STEPS_BACK: AtomicU64 = AtomicU64::new(0);
static TAKEOVERS: AtomicU64 = AtomicU64::new(0);

/// An interface name as the C side passes it (`struct rcan_ifname`):
/// NUL-terminated and NUL-padded.
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct IfName {
    name: [u8; IFNAME_MAX + 1],
}

impl IfName {
    /// The name's bytes, without the NUL.
    pub(crate) fn as_bytes(&self) -> &[u8] {
        let n = self.name.iter().position(|&b| b == 0).unwrap_or(IFNAME_MAX);
        &self.name[..n]
    }

    /// The name as a C string.
    fn as_cstr(&self) -> &CStr {
        let n = self.as_bytes().len();
        // `name[n]` is a NUL: `as_bytes` stops at the first one, and the
        // setter keeps byte 15 zero.
        CStr::from_bytes_with_nul(&self.name[..=n]).unwrap_or(kernel::c_str!("?"))
    }

    /// The name for log lines.
    pub(crate) fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("?")
    }
}

/// Validates and stores integer parameter `which` (C parameter callback
/// through `ticker_abi.rs`, process context). A false return makes the load, or the sysfs write,
/// fail with EINVAL.
pub(crate) fn param_set(which: u32, val: u32) -> bool {
    match which {
        PARAM_VEHICLE if timesvc::vehicle_valid(val) => VEHICLE.store(val, Ordering::Relaxed),
        PARAM_TIMEOUT_MS if timesvc::timeout_valid(val) => TIMEOUT_MS.store(val, Ordering::Relaxed),
        _ => return false,
    }
    true
}

/// Reads integer parameter `which` (C parameter callback).
pub(crate) fn param_get(which: u32) -> u32 {
    match which {
        PARAM_VEHICLE => VEHICLE.load(Ordering::Relaxed),
        _ => TIMEOUT_MS.load(Ordering::Relaxed),
    }
}

/// Validates and stores the `dev` parameter (C parameter callback, while
/// loading).
pub(crate) fn dev_set(name: IfName) -> bool {
    if name.name[IFNAME_MAX] != 0 || !timesvc::ifname_valid(name.as_bytes()) {
        return false;
    }
    let mut lo = [0u8; 8];
    let mut hi = [0u8; 8];
    lo.copy_from_slice(&name.name[..8]);
    hi.copy_from_slice(&name.name[8..]);
    DEV[0].store(u64::from_le_bytes(lo), Ordering::Relaxed);
    DEV[1].store(u64::from_le_bytes(hi), Ordering::Relaxed);
    true
}

/// Reads the `dev` parameter (C parameter callback).
pub(crate) fn dev_get() -> IfName {
    let mut name = [0u8; IFNAME_MAX + 1];
    name[..8].copy_from_slice(&DEV[0].load(Ordering::Relaxed).to_le_bytes());
    name[8..].copy_from_slice(&DEV[1].load(Ordering::Relaxed).to_le_bytes());
    IfName { name }
}

/// The load-time parameters: vehicle identifier and interface.
#[derive(Clone, Copy)]
pub(crate) struct Params {
    pub(crate) vehicle: u32,
    pub(crate) dev: IfName,
}

/// The current `vehicle` and `dev` parameters. Any context.
pub(crate) fn params() -> Params {
    Params {
        vehicle: VEHICLE.load(Ordering::Relaxed),
        dev: dev_get(),
    }
}

/// The takeover timeout `timeout_ms` (may change at run time).
pub(crate) fn timeout_ms() -> u32 {
    TIMEOUT_MS.load(Ordering::Relaxed)
}

fn timeout_ns() -> i64 {
    i64::from(timeout_ms()) * 1_000_000
}

/// Records a time frame from another source, received at `mono_ns`
/// (`rcan_rtime`'s receiver, NET_RX softirq).
pub(crate) fn saw_foreign(mono_ns: i64) {
    LAST_FOREIGN.fetch_max(mono_ns, Ordering::Relaxed);
}

/// When the service sends.
pub(crate) enum Policy {
    /// `rcan_time`: at every second.
    Always,
    /// `rcan_rtime`: while no other source sends.
    Redundant(Takeover),
}

/// Why the last second's frame did (not) go out; logged on change.
#[derive(Clone, Copy, PartialEq, Eq)]
enum DevState {
    Sending,
    Missing,
    Down,
    /// `rcan_send` or the allocation failed with this (negative) errno.
    Failed(i32),
}

/// What only `TICK`'s callback uses.
pub(crate) struct TickState {
    params: Params,
    source: u8,
    policy: Policy,
    dev_state: DevState,
    /// When `TICK`'s expiry is due on the monotonic clock, as computed
    /// when it was last armed here or in [`start`] (`Arm::due_mono`);
    /// `WATCH` re-arming `TICK` leaves it stale, which `on_timer` allows.
    due_mono: i64,
}

impl TickState {
    /// Whether to send at the boundary due at `mono` (`TimerFire::due`);
    /// runs the takeover state machine.
    fn decide(&mut self, mono: i64) -> bool {
        let Policy::Redundant(t) = &mut self.policy else {
            return true;
        };
        let last = LAST_FOREIGN.load(Ordering::Relaxed);
        let last = (last != NEVER).then_some(last);
        let d = t.tick(mono, last, timeout_ns());
        match d {
            Decision::TakeOver => {
                TAKEOVERS.fetch_add(1, Ordering::Relaxed);
                match last {
                    Some(l) => pr_info!(
                        "{}: no time frame from another source for {} ms: taking over\n",
                        self.params.dev.as_str(),
                        (mono - l) / 1_000_000
                    ),
                    None => pr_info!(
                        "{}: no time frame from another source since start: taking over\n",
                        self.params.dev.as_str()
                    ),
                }
            }
            Decision::HandBack => pr_info!(
                "{}: time frame from another source: handing back\n",
                self.params.dev.as_str()
            ),
            Decision::Send | Decision::Silent => {}
        }
        d.sends()
    }

    /// Sends the frame naming `second`, logging a change of the outcome.
    fn send(&mut self, second: i64) {
        let state = match send_frame(&self.params, self.source, second) {
            Ok(()) => {
                SENT.fetch_add(1, Ordering::Relaxed);
                DevState::Sending
            }
            Err(s) => {
                SKIPPED.fetch_add(1, Ordering::Relaxed);
                s
            }
        };
        if state != self.dev_state {
            let dev = self.params.dev.as_str();
            match state {
                DevState::Sending => pr_info!("{}: sending time frames again\n", dev),
                DevState::Missing => pr_info!("{}: no such device: skipping seconds\n", dev),
                DevState::Down => pr_info!("{}: device down: skipping seconds\n", dev),
                DevState::Failed(e) => pr_info!("{}: send failed ({}): skipping seconds\n", dev, e),
            }
            self.dev_state = state;
        }
    }
}

/// Builds the time frame for `second` and sends it on the device named in
/// `p`, with local loopback. Softirq context.
fn send_frame(p: &Params, source: u8, second: i64) -> core::result::Result<(), DevState> {
    let frame = TimeFrame::for_second(second, source).encode(p.vehicle);
    let dev = DevRef::by_name(Net::init(), p.dev.as_cstr()).ok_or(DevState::Missing)?;
    if !dev.is_up() {
        return Err(DevState::Down);
    }
    let enomem = DevState::Failed(ENOMEM.to_errno());
    let skb =
        alloc_frame(&dev, &AnyFrame::Classic(frame), crate::glue::GFP_ATOMIC).ok_or(enomem)?;
    // Before sending: the echo may come back on another CPU before
    // rcan_send returns.
    let own = u64::from_ne_bytes(frame.data);
    OWN_ECHO.store(own, Ordering::Release);
    rcan_api::send(skb, &dev, true).map_err(|e| {
        // Not sent: no echo will come.
        let _ = OWN_ECHO.compare_exchange(own, 0, Ordering::AcqRel, Ordering::Relaxed);
        if e == crate::glue::neterr::ENETDOWN() {
            DevState::Down
        } else {
            DevState::Failed(e.to_errno())
        }
    })
}

/// `TICK`'s callback.
pub(crate) struct Tick;

impl HrTimerCallback for Tick {
    type State = TickState;

    fn run(timer: &'static HrTimer<Tick>, st: &mut TickState) {
        if STOPPING.load(Ordering::Acquire) {
            return;
        }
        let (real, mono) = (ktime_get_real_ns(), ktime_get_mono_ns());
        let fire = timesvc::on_timer(real, mono, timer.armed_for(), st.due_mono);
        timer.start(fire.next.real);
        st.due_mono = fire.next.due_mono;
        WATCH.start(fire.next.watchdog_mono);
        if let Some(second) = fire.second {
            if st.decide(fire.due) {
                // Counted before sending, so that the count at module
                // exit covers every frame that went out after a gap.
                MISSED.fetch_add(fire.missed, Ordering::Relaxed);
                st.send(second);
            }
        }
    }
}

/// `WATCH`'s callback.
pub(crate) struct Watch;

impl HrTimerCallback for Watch {
    type State = ();

    fn run(timer: &'static HrTimer<Watch>, _st: &mut ()) {
        if STOPPING.load(Ordering::Acquire) {
            return;
        }
        let (real, mono) = (ktime_get_real_ns(), ktime_get_mono_ns());
        let w = timesvc::on_watchdog(real, mono, TICK.armed_for());
        if let Some(r) = w.rearm_real {
            TICK.start(r);
            STEPS_BACK.fetch_add(1, Ordering::Relaxed);
            pr_info!("clock stepped back: waiting for the next second of the new time\n");
        }
        timer.start(w.watchdog_mono);
    }
}

/// Sends at every whole second of `CLOCK_REALTIME`.
static TICK: HrTimer<Tick> = HrTimer::new();
/// Catches `TICK` stuck after a backward clock step.
static WATCH: HrTimer<Watch> = HrTimer::new();

/// Starts the ticker: `rcan_time` (`redundant` false, source 1) or
/// `rcan_rtime` (true, source 2, passive for `timeout_ms` first). Module
/// init, process context.
pub(crate) fn start(scope: &ModuleScope, redundant: bool) -> Result<Params> {
    // rcan_time only sends: nothing it registers checks the ABI for it.
    rcan_api::abi_check()?;
    let params = params();
    let (real, mono) = (ktime_get_real_ns(), ktime_get_mono_ns());
    let (source, policy) = if redundant {
        (SOURCE_RTIME, Policy::Redundant(Takeover::new(mono)))
    } else {
        (SOURCE_TIME, Policy::Always)
    };
    let arm = timesvc::arm(real, mono);
    let state = TickState {
        params,
        source,
        policy,
        dev_state: DevState::Sending,
        due_mono: arm.due_mono,
    };
    TICK.init(scope, ClockId::RealTime, HrTimerMode::AbsoluteSoft, state)?;
    WATCH.init(scope, ClockId::Monotonic, HrTimerMode::AbsoluteSoft, ())?;
    TICK.start(arm.real);
    WATCH.start(arm.watchdog_mono);
    Ok(params)
}

/// Stops the ticker for good: when this returns, no callback runs or is
/// queued, so no frame is sent any more. Module exit, process context.
pub(crate) fn stop() {
    STOPPING.store(true, Ordering::SeqCst);
    // Callbacks that started before STOPPING was set may still re-arm
    // either timer once: the first cancel waits out TICK's, the second
    // WATCH's (which may have re-armed TICK), the third removes that.
    // Callbacks starting later see STOPPING and arm nothing.
    TICK.cancel();
    WATCH.cancel();
    TICK.cancel();
}

/// Counters for the exit log line. Without clock steps, `sent + skipped +
/// missed` is the number of seconds the service had to announce.
pub(crate) struct Stats {
    pub(crate) sent: u64,
    pub(crate) skipped: u64,
    /// Seconds missed because the timer callback ran late (late timer).
    pub(crate) missed: u64,
    pub(crate) steps_back: u64,
    pub(crate) takeovers: u64,
}

/// The counters (after [`stop`]: final).
pub(crate) fn stats() -> Stats {
    Stats {
        sent: SENT.load(Ordering::Relaxed),
        skipped: SKIPPED.load(Ordering::Relaxed),
        missed: MISSED.load(Ordering::Relaxed),
        steps_back: STEPS_BACK.load(Ordering::Relaxed),
        takeovers: TAKEOVERS.load(Ordering::Relaxed),
    }
}

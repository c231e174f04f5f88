// SPDX-License-Identifier: GPL-2.0

//! The CAN device layer, drivers' side: what a driver implements
//! ([`CanDevice`]) so that `ip link set canX type can ...` and
//! `ip -details link show canX` reach it, and the device-layer state it
//! keeps per device ([`CanDev`]).
//!
//! The rtnetlink link kind "can" itself (attribute parsing and encoding)
//! is registered by module `rcan_dev` (`drivers/net/can/dev/`, glue in
//! [`super::link`]); a driver module compiles this file, and its devices
//! carry `rcan_dev`'s `rtnl_link_ops` (so the kernel routes their "can"
//! requests there) and, in `dev->ml_priv`, a pointer to this driver's
//! [`CanDevHooks`]: the C ABI below, through which `rcan_dev` calls back
//! into [`Adapter`]. One `CanDevHooks` exists per driver type (a promoted
//! constant); one [`CanDev`] per device, inside the driver's private
//! data. Using `rcan_dev`'s exported `rcan_can_link_ops` makes every
//! driver module depend on `rcan_dev`, so `rcan_dev` (and the ops the
//! devices point to) cannot go while a device exists.
//!
//! Contexts: every hook runs in process context under RTNL (rtnetlink
//! requests and dumps; in 6.12 `RTM_GETLINK` dumps hold RTNL too). The
//! settings are changed only there, but also read by the driver's `open`
//! (RTNL) and by `sja1000config`'s ioctl (no RTNL), hence their own lock;
//! the statistics are atomics, counted from the interrupt handler.

use crate::glue::bindings;
use crate::glue::hrtimer::ktime_get_mono_ns;
use crate::glue::jobtimer::{JobCallback, JobRef, JobTimers};
use crate::glue::lock::{new_irq_spinlock, IrqSpinLock};
use crate::glue::netdev::{Dev, DevRef, Driver, NetDev};
use crate::rcan_core::bittiming::{Bittiming, BittimingConst, Msg, BITTIMING_LEN};
use crate::rcan_core::candev::{self, CanState, Settings};
use crate::rcan_core::frame::{CANFD_MTU, CAN_MTU};
use core::marker::PhantomData;
use core::sync::atomic::{AtomicU32, Ordering};
use kernel::ffi;
use kernel::prelude::*;

// ---------------------------------------------------------------------
// The C ABI between rcan_dev and the driver modules. All modules are
// built from one tree, so it may change freely; it is C only because the
// modules are separate crates linked by the module loader.
// ---------------------------------------------------------------------

/// One `RTM_NEWLINK` request's "can" attributes, parsed by `rcan_dev`
/// (mirror of [`candev::Request`] with a fixed layout).
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub(crate) struct LinkReq {
    pub(crate) has_ctrlmode: bool,
    pub(crate) ctrlmode_flags: u32,
    pub(crate) ctrlmode_mask: u32,
    pub(crate) has_bittiming: bool,
    /// `struct can_bittiming`, native endian.
    pub(crate) bittiming: [u8; BITTIMING_LEN],
    pub(crate) has_restart_ms: bool,
    pub(crate) restart_ms: u32,
    pub(crate) restart: bool,
    pub(crate) has_data_bittiming: bool,
    pub(crate) data_bittiming: [u8; BITTIMING_LEN],
    pub(crate) tdc: bool,
    pub(crate) has_termination: bool,
    pub(crate) termination: u16,
}

impl LinkReq {
    /// The request as the rules of [`candev`] take it.
    pub(crate) fn to_request(&self) -> candev::Request {
        candev::Request {
            ctrlmode: self
                .has_ctrlmode
                .then_some((self.ctrlmode_flags, self.ctrlmode_mask)),
            bittiming: self
                .has_bittiming
                .then(|| Bittiming::from_ne_bytes(&self.bittiming)),
            restart_ms: self.has_restart_ms.then_some(self.restart_ms),
            restart: self.restart,
            data_bittiming: self
                .has_data_bittiming
                .then(|| Bittiming::from_ne_bytes(&self.data_bittiming)),
            tdc: self.tdc,
            termination: self.has_termination.then_some(self.termination),
        }
    }
}

/// Room for an extended-ack message (`NETLINK_MAX_FMTMSG_LEN`).
pub(crate) const LINK_MSG_LEN: usize = 80;

/// The extended-ack text of a request (an error's, or a warning's when
/// the request succeeded), NUL-terminated; empty: none.
#[repr(C)]
pub(crate) struct LinkMsg {
    pub(crate) text: [u8; LINK_MSG_LEN],
}

impl LinkMsg {
    pub(crate) const fn new() -> Self {
        LinkMsg {
            text: [0; LINK_MSG_LEN],
        }
    }

    /// Stores `msg`'s text (cut to fit).
    pub(crate) fn set(&mut self, msg: &Msg) {
        struct W<'a>(&'a mut [u8; LINK_MSG_LEN], usize);
        impl core::fmt::Write for W<'_> {
            fn write_str(&mut self, s: &str) -> core::fmt::Result {
                for b in s.bytes() {
                    if self.1 + 1 < LINK_MSG_LEN {
                        self.0[self.1] = b;
                        self.1 += 1;
                    }
                }
                Ok(())
            }
        }
        self.text = [0; LINK_MSG_LEN];
        let mut w = W(&mut self.text, 0);
        let _ = core::fmt::write(&mut w, format_args!("{msg}"));
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.text[0] == 0
    }
}

/// `struct can_device_stats` (what `ip -s -d` prints as "re-started
/// bus-errors arbit-lost error-warn error-pass bus-off"), in its C order.
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub(crate) struct CanDeviceStats {
    pub(crate) bus_error: u32,
    pub(crate) error_warning: u32,
    pub(crate) error_passive: u32,
    pub(crate) bus_off: u32,
    pub(crate) arbitration_lost: u32,
    pub(crate) restarts: u32,
}

/// What `ip -details` shows of a device, collected by the driver's side
/// for `rcan_dev` to encode.
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct LinkInfo {
    /// The bit timing (`bitrate` 0: none set, not reported).
    pub(crate) bittiming: [u8; BITTIMING_LEN],
    /// `struct can_bittiming_const`: name (NUL-padded) and limits.
    pub(crate) btc_name: [u8; 16],
    pub(crate) btc: [u32; 8],
    /// The data bit timing (CAN FD; `bitrate` 0: none set, not reported).
    pub(crate) data_bittiming: [u8; BITTIMING_LEN],
    /// Whether the device has data bit-timing limits (CAN FD): then
    /// `dbtc_name`/`dbtc` are reported as `IFLA_CAN_DATA_BITTIMING_CONST`.
    pub(crate) has_dbtc: bool,
    pub(crate) dbtc_name: [u8; 16],
    pub(crate) dbtc: [u32; 8],
    pub(crate) clock_hz: u32,
    /// `enum can_state`.
    pub(crate) state: u32,
    pub(crate) ctrlmode: u32,
    pub(crate) ctrlmode_supported: u32,
    pub(crate) restart_ms: u32,
    pub(crate) txerr: u16,
    pub(crate) rxerr: u16,
    pub(crate) stats: CanDeviceStats,
}

/// The driver's entry points that `rcan_dev` calls, found in
/// `dev->ml_priv` of a device whose `rtnl_link_ops` are `rcan_dev`'s.
#[repr(C)]
pub(crate) struct CanDevHooks {
    /// Applies a request to `dev`; returns 0 or a negative errno, and the
    /// extended-ack text in `msg`. Process context, RTNL held.
    pub(crate) changelink: unsafe extern "C" fn(
        dev: *mut bindings::net_device,
        req: *const LinkReq,
        msg: *mut LinkMsg,
    ) -> ffi::c_int,
    /// Fills `out` with the device's state. Process context, RTNL held.
    pub(crate) info: unsafe extern "C" fn(dev: *const bindings::net_device, out: *mut LinkInfo),
}

extern "C" {
    /// The "can" `rtnl_link_ops` registered by `rcan_dev`
    /// (`drivers/net/can/dev/candev_c.c`, `EXPORT_SYMBOL_GPL`).
    static rcan_can_link_ops: kernel::types::Opaque<bindings::rtnl_link_ops>;
}

/// What a CAN device's `net_device` gets at allocation so that rtnetlink
/// routes its "can" requests to `rcan_dev` and from there to the driver.
/// Only [`link_setup`] makes one.
pub(crate) struct LinkSetup {
    pub(in crate::glue) ops: *const bindings::rtnl_link_ops,
    pub(in crate::glue) hooks: *const CanDevHooks,
}

/// The [`LinkSetup`] of driver `T`'s devices.
pub(crate) fn link_setup<T: CanDevice>() -> LinkSetup {
    LinkSetup {
        // SAFETY: only the address of the exported static is taken; the
        // symbol reference makes this module depend on rcan_dev, which
        // therefore outlives every device pointing at it.
        ops: unsafe { rcan_can_link_ops.get() }.cast_const(),
        hooks: &Adapter::<T>::HOOKS,
    }
}

/// The settings a device of driver `T` whose bit timing counts
/// `clock_hz` starts with for the module parameters' rates `preset`
/// ([`candev::Preset::settings`] against `T`'s limits): the same search
/// as `ip link set canX type can bitrate N`. Any context.
pub(crate) fn preset_settings<T: CanDevice>(
    preset: &candev::Preset,
    clock_hz: u32,
) -> core::result::Result<Settings, candev::PresetError> {
    preset.settings(&candev::Device {
        clock_hz,
        ..Adapter::<T>::device()
    })
}

// ---------------------------------------------------------------------
// The typed side.
// ---------------------------------------------------------------------

/// The CAN device statistics counted by drivers (`struct
/// can_device_stats`).
#[derive(Clone, Copy)]
pub(crate) enum CanStat {
    BusError,
    ErrorWarning,
    ErrorPassive,
    BusOff,
    ArbitrationLost,
    Restarts,
}

/// The device-layer state of one CAN device (mainline's `struct
/// can_priv` fields the device layer owns), kept in the driver's private
/// data and reached through [`CanDevice::can_dev`].
pub(crate) struct CanDev {
    /// Bit timing, control modes, restart-ms. Changed under RTNL (and by
    /// `sja1000config` with the device down); the lock makes every read a
    /// consistent copy. Never held across a call out. Lock order: a
    /// driver's chip lock, then this (the interrupt handler reads
    /// `restart_ms` at bus-off).
    settings: IrqSpinLock<Settings>,
    /// `struct can_device_stats`, counted from any context.
    stats: [AtomicU32; 6],
    /// The bus-off restart timer (mainline's `restart_work`), there from
    /// `open` ([`ctrl::open`](super::ctrl::open), the only caller of
    /// [`CanDev::arm_restart`]) to `stop` ([`CanDev::disarm_restart`]);
    /// armed from the interrupt handler at bus-off when `restart-ms` is
    /// not 0. The lock only guards the `Option` (taken in any context,
    /// innermost); the timer is dropped outside it.
    restart: IrqSpinLock<Option<JobTimers<RestartJob>>>,
}

/// What the restart timer needs: the device, held (`dev_hold`), and the
/// driver's restart entry point ([`Adapter::restart_expired`] of its
/// driver).
///
/// # Invariants
///
/// `dev` is a device registered by `Registration` for the driver whose
/// `restart_expired` `hook` is.
struct RestartData {
    dev: DevRef,
    /// # Safety (of calling it)
    ///
    /// The argument is a device registered by `Registration` for the
    /// driver whose adapter this is, whose private data stays initialised
    /// for the call.
    hook: unsafe fn(*mut bindings::net_device),
}

// SAFETY: `DevRef` is Send; `&RestartData` only reads the device pointer
// and the function pointer, and the device's own methods are callable
// from any CPU.
unsafe impl Sync for RestartData {}

/// The restart timer's callback.
struct RestartJob;

impl JobCallback for RestartJob {
    type Data = RestartData;

    /// `restart-ms` after bus-off: restart the controller (mainline
    /// `can_restart`). HRTIMER_SOFTIRQ softirq context; the driver's
    /// restart takes only spinlocks.
    fn expired(job: JobRef<'_, Self>, _which: usize) {
        let d = job.data();
        // The reference `d.dev` holds keeps its Registration's drop inside
        // `unregister_netdev` (which waits for every reference) until this
        // timer is dropped, after its callback finished.
        // SAFETY: a device of the hook's driver (type invariant), whose
        // private data is therefore initialised for the call.
        unsafe { (d.hook)(d.dev.as_ptr()) };
    }
}

impl CanDev {
    /// A device without bit timing (as mainline's: `up` is refused until
    /// one is set), or with `preset`. Process context (allocates the
    /// lock).
    pub(crate) fn new(preset: Settings) -> Result<Self> {
        Ok(CanDev {
            settings: new_irq_spinlock!(preset, "CanDev::settings")?,
            stats: Default::default(),
            restart: new_irq_spinlock!(None, "CanDev::restart")?,
        })
    }

    /// Prepares the bus-off restart timer of `dev`, in `dev`'s own
    /// [`CanDev`] (`T::can_dev` of its private data), which it returns:
    /// the timer restarts the device whose state it lives in, never
    /// another. The timer holds a reference on the device, so it can
    /// never run on a freed one: a timer left armed past the device's
    /// `stop` would hold up its unregistration instead (a leak, not a use
    /// after free). Only [`ctrl::open`](super::ctrl::open) calls it (the
    /// driver's `open`, process context, RTNL held), and the
    /// [`ctrl::Opening`](super::ctrl::Opening)'s drop or
    /// [`ctrl::stop`](super::ctrl::stop) undoes it.
    pub(super) fn arm_restart<T: CanDevice>(dev: &Dev<T>) -> Result<&CanDev> {
        let can = T::can_dev(dev.priv_data());
        // INVARIANT: `dev` is a `Dev<T>`, registered by Registration for
        // `T`, whose adapter the hook is.
        let t = JobTimers::new(
            RestartData {
                dev: dev.hold(),
                hook: Adapter::<T>::restart_expired,
            },
            dev,
        )?;
        let old = can.restart.lock().replace(t);
        drop(old);
        Ok(can)
    }

    /// Cancels the restart timer and waits for a running restart (the
    /// driver's `stop`, process context; call it before stopping the
    /// chip, so that no restart starts it again).
    pub(crate) fn disarm_restart(&self) {
        let t = self.restart.lock().take();
        drop(t);
    }

    /// The controller went bus-off (mainline `can_bus_off`): carrier off,
    /// the kernel log says so, and with `restart-ms` set the restart
    /// timer is armed. Any context (the interrupt handler).
    pub(crate) fn bus_off(&self, dev: &NetDev) {
        let ms = self.settings.lock().restart_ms;
        if ms != 0 {
            pr_info!("{}: bus-off, scheduling restart in {} ms\n", dev.name(), ms);
        } else {
            pr_info!("{}: bus-off\n", dev.name());
        }
        dev.set_carrier(false);
        if ms != 0 {
            let at = ktime_get_mono_ns() as u64 + u64::from(ms) * 1_000_000;
            if let Some(t) = self.restart.lock().as_ref() {
                t.get().start(0, at);
            }
        }
    }

    /// A copy of the settings. Any context.
    pub(crate) fn settings(&self) -> Settings {
        *self.settings.lock()
    }

    /// `ip link set canX mtu N` for a driver with FD (its
    /// `Driver::change_mtu`, process context, RTNL held): mainline
    /// `can_change_mtu` ([`candev::change_mtu`]): 72 turns CAN FD on, 16
    /// off; while up `EBUSY`. The glue stores the MTU on success.
    pub(crate) fn change_mtu<T: CanDevice>(&self, dev: &Dev<T>, new_mtu: u32) -> Result {
        let mut s = self.settings.lock();
        candev::change_mtu(&Adapter::<T>::device(), &mut s, dev.is_up(), new_mtu)
            .map_err(|e| crate::glue::errno(e.errno))
    }

    /// Replaces the bit timing and sets or clears triple sampling (the
    /// thesis' `sja1000config`, which writes the registers): the device
    /// must be down. Any context.
    pub(crate) fn set_registers_timing(&self, bt: Bittiming, triple: bool) {
        let mut s = self.settings.lock();
        s.bittiming = bt;
        if triple {
            s.ctrlmode |= candev::ctrlmode::THREE_SAMPLES;
        } else {
            s.ctrlmode &= !candev::ctrlmode::THREE_SAMPLES;
        }
    }

    /// The settings the device may come up with (mainline
    /// `open_candev`): without a bit timing, or with CAN FD on and no
    /// data bit timing (or a slower one), `EINVAL`, and the kernel log
    /// says why for `dev` ("bit-timing not yet defined", "incorrect/missing
    /// data bit-timing"). Process context.
    pub(crate) fn open_check(&self, dev_name: &str) -> Result<Settings> {
        let s = self.settings();
        if let Err(why) = candev::open(&s) {
            pr_err!("{}: {}\n", dev_name, why);
            return Err(EINVAL);
        }
        Ok(s)
    }

    /// Counts one event. Any context.
    pub(crate) fn count(&self, which: CanStat) {
        self.add(which, 1);
    }

    /// Counts `n` events. Any context.
    pub(crate) fn add(&self, which: CanStat, n: u32) {
        if n != 0 {
            self.stats[which as usize].fetch_add(n, Ordering::Relaxed);
        }
    }

    /// A copy of the statistics. Any context.
    pub(crate) fn stats(&self) -> CanDeviceStats {
        let g = |i: CanStat| self.stats[i as usize].load(Ordering::Relaxed);
        CanDeviceStats {
            bus_error: g(CanStat::BusError),
            error_warning: g(CanStat::ErrorWarning),
            error_passive: g(CanStat::ErrorPassive),
            bus_off: g(CanStat::BusOff),
            arbitration_lost: g(CanStat::ArbitrationLost),
            restarts: g(CanStat::Restarts),
        }
    }
}

/// A CAN controller driver seen by the device layer (mainline's
/// `can_priv` callbacks and constants).
///
/// Contexts: every method is called in process context with RTNL held,
/// from an `ip link` request or dump (the driver's own callers may use
/// them elsewhere).
pub(crate) trait CanDevice: Driver {
    /// The controller's bit-timing limits (`IFLA_CAN_BITTIMING_CONST`).
    const BITTIMING_CONST: &'static BittimingConst;
    /// The data-phase limits of a CAN FD controller
    /// (`IFLA_CAN_DATA_BITTIMING_CONST`); `None` (the default): no CAN
    /// FD, `dbitrate` is refused with `EOPNOTSUPP`. A driver with FD
    /// also announces [`candev::ctrlmode::FD`], implements
    /// `Driver::change_mtu` with [`CanDev::change_mtu`], and starts with
    /// MTU 16 (FD off, as mainline).
    const DATA_BITTIMING_CONST: Option<&'static BittimingConst> = None;
    /// Control modes the driver implements (`ctrlmode_supported`).
    const CTRLMODE_SUPPORTED: u32;
    /// Whether the driver can restart the controller after bus-off
    /// ([`CanDevice::restart`]; mainline: it has `do_set_mode`).
    const CAN_RESTART: bool;

    /// The device-layer state of the device.
    fn can_dev(p: &Self::Priv) -> &CanDev;
    /// The clock the bit timing counts, in Hz (`IFLA_CAN_CLOCK`).
    fn clock_hz(p: &Self::Priv) -> u32;
    /// The controller's error state; [`CanState::Stopped`] while down.
    fn state(dev: &Dev<Self>, p: &Self::Priv) -> CanState;
    /// The (TX, RX) error counters.
    fn berr_counter(dev: &Dev<Self>, p: &Self::Priv) -> (u16, u16);
    /// Restarts a bus-off controller now (mainline `can_restart`:
    /// flush the echo, send `CAN_ERR_RESTARTED`, carrier on, count the
    /// restart, `do_set_mode(CAN_MODE_START)`): for `ip link set canX
    /// type can restart` (process context, RTNL) and the `restart-ms`
    /// timer (softirq context). Must not sleep.
    fn restart(dev: &Dev<Self>, p: &Self::Priv) -> Result;
}

/// The trampolines `rcan_dev` calls for devices of `T`.
struct Adapter<T: CanDevice>(PhantomData<T>);

impl<T: CanDevice> Adapter<T> {
    const HOOKS: CanDevHooks = CanDevHooks {
        changelink: Self::changelink,
        info: Self::info,
    };

    /// The restart timer's entry (softirq context).
    ///
    /// # Safety
    ///
    /// `dev` is a device registered by `Registration` for driver `T`
    /// whose private data stays initialised for the call.
    unsafe fn restart_expired(dev: *mut bindings::net_device) {
        // SAFETY: per the contract (what `from_cookie` needs: the device
        // and its private data valid for the call).
        let (d, p) = unsafe { crate::glue::netdev::from_cookie::<T>(dev) };
        if let Err(e) = T::restart(d, p) {
            pr_err!("{}: restart failed: {:?}\n", d.name(), e);
        }
    }

    fn device() -> candev::Device {
        candev::Device {
            btc: Some(T::BITTIMING_CONST),
            dbtc: T::DATA_BITTIMING_CONST,
            clock_hz: 0,
            ctrlmode_supported: T::CTRLMODE_SUPPORTED,
            ctrlmode_static: 0,
            can_restart: T::CAN_RESTART,
        }
    }

    /// # Safety
    ///
    /// `dev` is a registered device of driver `T` (its `ml_priv` is our
    /// HOOKS, which only [`link_setup`] for `T` puts there), `req` and
    /// `msg` valid for the call; RTNL held.
    unsafe extern "C" fn changelink(
        dev: *mut bindings::net_device,
        req: *const LinkReq,
        msg: *mut LinkMsg,
    ) -> ffi::c_int {
        // SAFETY: per the contract: a registered device of `T`, which
        // stays registered while RTNL is held.
        let (d, p) = unsafe { crate::glue::netdev::from_cookie::<T>(dev) };
        // SAFETY: valid for the call (contract).
        let (req, msg) = unsafe { (&*req, &mut *msg) };
        let cd = T::can_dev(p);
        let mut device = Self::device();
        device.clock_hz = T::clock_hz(p);
        let state = T::state(d, p);
        let mut s = cd.settings();
        let r = candev::changelink(&device, &mut s, d.is_up(), state, &req.to_request());
        // Changes made before a refusal stay, as in mainline.
        *cd.settings.lock() = s;
        if req.has_ctrlmode {
            // Mainline's can_changelink sets the MTU from the FD mode
            // whenever control modes are set (also when a later attribute
            // is refused); a refused control mode left FD, and so the
            // MTU, as it was.
            let mtu = if s.ctrlmode & candev::ctrlmode::FD != 0 {
                CANFD_MTU
            } else {
                CAN_MTU
            } as u32;
            if d.mtu() != mtu {
                // Readers (the transmit paths) read the MTU without RTNL;
                // this is mainline's plain store under RTNL.
                // SAFETY: a registered device (contract); RTNL, the MTU's
                // writers' lock, is held.
                unsafe { core::ptr::write_volatile(&raw mut (*dev).mtu, mtu) };
            }
        }
        match r {
            Ok(ch) => {
                // The last warning wins, as with mainline's extack.
                if let Some(w) = ch.bittiming.and_then(|c| c.warning) {
                    msg.set(&w);
                }
                if let Some(w) = ch.data_bittiming.and_then(|c| c.warning) {
                    msg.set(&w);
                }
                if ch.restart_now {
                    if let Err(e) = T::restart(d, p) {
                        return e.to_errno();
                    }
                }
                0
            }
            Err(e) => {
                if let Some(m) = &e.msg {
                    msg.set(m);
                }
                crate::glue::errno(e.errno).to_errno()
            }
        }
    }

    /// # Safety
    ///
    /// As for [`Self::changelink`]; `out` valid for writes.
    unsafe extern "C" fn info(dev: *const bindings::net_device, out: *mut LinkInfo) {
        // SAFETY: per the contract.
        let (d, p) = unsafe { crate::glue::netdev::from_cookie::<T>(dev.cast_mut()) };
        let cd = T::can_dev(p);
        let s = cd.settings();
        let limits = |btc: &BittimingConst| {
            let mut name = [0u8; 16];
            for (n, b) in name.iter_mut().zip(btc.name.bytes().take(15)) {
                *n = b;
            }
            (
                name,
                [
                    btc.tseg1_min,
                    btc.tseg1_max,
                    btc.tseg2_min,
                    btc.tseg2_max,
                    btc.sjw_max,
                    btc.brp_min,
                    btc.brp_max,
                    btc.brp_inc,
                ],
            )
        };
        let (btc_name, btc) = limits(T::BITTIMING_CONST);
        let (dbtc_name, dbtc) = T::DATA_BITTIMING_CONST
            .map(limits)
            .unwrap_or(([0; 16], [0; 8]));
        let (txerr, rxerr) = T::berr_counter(d, p);
        let info = LinkInfo {
            bittiming: s.bittiming.to_ne_bytes(),
            btc_name,
            btc,
            data_bittiming: s.data_bittiming.to_ne_bytes(),
            has_dbtc: T::DATA_BITTIMING_CONST.is_some(),
            dbtc_name,
            dbtc,
            clock_hz: T::clock_hz(p),
            state: T::state(d, p) as u32,
            ctrlmode: s.ctrlmode,
            ctrlmode_supported: T::CTRLMODE_SUPPORTED,
            restart_ms: s.restart_ms,
            txerr,
            rxerr,
            stats: cd.stats(),
        };
        // SAFETY: valid for writes (contract).
        unsafe { out.write(info) };
    }
}

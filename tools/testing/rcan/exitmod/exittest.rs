// SPDX-License-Identifier: GPL-2.0

//! `rcan_exittest`: a test-only module for the VM test
//! `teardown_exit_sweeps` (`tests/vm/src/cases/teardown.rs`, issue 39).
//! Safe code, as every protocol and driver file, that registers one of
//! each thing whose teardown the glue's module exit owns
//! (`rust/glue/module.rs`) and never undoes any of it itself:
//!
//! * a protocol, [`CANPROTO_EXITTEST`] (`SOCK_DGRAM`), whose registration
//!   sits in a `static` (never dropped) until the first `bind` of one of
//!   its sockets takes it out and drops it, while that socket is open: a
//!   protocol module dropping its `ProtoRegistration` early. The protocol
//!   must keep working (more sockets, the open one closing) and its
//!   sockets pin the module as before. Its `release` does nothing: the
//!   glue takes each closed socket off the protocol's socket set (a
//!   protocol has no such duty), and its netdevice notifier, which
//!   counts the open sockets it is shown, logs the count for the test;
//! * an in-kernel receiver for CAN identifier [`RX_ID`] on every device,
//!   forgotten (`mem::forget`): after `rmmod`, a frame with that
//!   identifier must not call into the freed module;
//! * a network device (`rcanexit%d`, a CAN device that drops what it is
//!   given), forgotten: it must be gone after `rmmod`;
//! * a job whose timer re-arms itself every [`TICK_NS`], forgotten: it
//!   must not fire after `rmmod`;
//! * a second network device (`rcanexit1`), kept in a `static` until a
//!   socket's `connect` moves it into that socket's `Proto::Data` and
//!   arms a job that holds a reference to the socket and drops it
//!   [`PUT_AFTER_NS`] later, from the timer softirq: after the socket's
//!   close, that is the last reference, so the socket's data (the device
//!   registration, whose drop sleeps) goes when the sock is freed outside
//!   process context. The glue must drop it in process context: the
//!   device must go, without a kernel report.
//!
//! Each of these, left behind by a glue that does not sweep it, was seen
//! to crash the kernel (architecture.rst, "Registrations forgotten at
//! rmmod"); the test checks that none does.
#![forbid(unsafe_code)]

use crate::glue::can::ctrl;
use crate::glue::can::proto::{
    rx_set_kernel, CanProtocol, KernelRx, NetdevEvent, ProtoModule, ProtoRegistration, RxFilter,
    Sockets, RX_FILTER_CAN_ID, SOCK_DGRAM,
};
use crate::glue::hrtimer::ktime_get_mono_ns;
use crate::glue::neterr::EOPNOTSUPP;
use crate::glue::jobtimer::{JobCallback, JobRef, JobTimers};
use crate::glue::module::{ModuleScope, ScopedModule};
use crate::glue::netdev::{Dev, Driver, NetDev, Registration, Setup, Xmit};
use crate::glue::skb::Skb;
use crate::glue::lock::{new_irq_spinlock, IrqSpinLock};
use crate::glue::sock::{Msg, Proto, Sock, SockRef};
use crate::glue::sync::{Rtnl, RtnlLocked};
use crate::rcan_core::frame::CAN_MTU;
use core::sync::atomic::{AtomicU64, Ordering};
use kernel::c_str;
use kernel::prelude::*;

/// The protocol number, the highest of the table (`CANPROTO_MAX - 1`):
/// no real protocol uses it.
pub(crate) const CANPROTO_EXITTEST: i32 = 23;
/// The CAN identifier the forgotten kernel receiver listens to.
pub(crate) const RX_ID: u32 = 0x7e5;
/// The period of the forgotten job's timer: 50 ms.
const TICK_NS: u64 = 50_000_000;
/// How long after `connect` the putter job drops its socket reference:
/// 100 ms, after the test's close.
const PUT_AFTER_NS: u64 = 100_000_000;

/// The protocol: sockets that can be created, bound (which drops the
/// protocol's registration) and closed; nothing else.
pub(crate) struct ExitProto;

/// The protocol's sockets and registrations.
static MODULE: ProtoModule<ExitProto> = ProtoModule::new();

/// The protocol's registration until the first `bind` drops it.
/// Protected by RTNL.
static REG: RtnlLocked<Option<ProtoRegistration<ExitProto>>> = RtnlLocked::new(None);

/// The second device until a `connect` moves it into its socket's data.
/// Protected by RTNL.
static HELD: RtnlLocked<Option<Registration<SinkDev>>> = RtnlLocked::new(None);

impl Proto for ExitProto {
    /// The device `connect` moved here, if any: dropped with the sock.
    type Data = Option<Registration<SinkDev>>;
    type Shared = ();

    fn new_data() -> Self::Data {
        None
    }
    fn new_shared() {}

    /// Process context. Nothing to undo: the glue takes the sock off
    /// the protocol's socket set when this returns.
    fn release(_sk: &Sock<Self>) {}

    /// Drops the protocol's registration, if it is still in [`REG`], while
    /// this socket is open: what a protocol may do from safe code. Process
    /// context (the registration's drop may sleep), RTNL not held.
    fn bind(_sk: &Sock<Self>, _addr: &[u8]) -> Result {
        let reg = REG.get(&mut Rtnl::lock()).take();
        let dropped = reg.is_some();
        drop(reg);
        if dropped {
            pr_info!("dropped the protocol registration with a socket open\n");
        }
        Ok(())
    }

    /// Moves the held device into this socket's data and arms a job that
    /// drops a reference to the socket [`PUT_AFTER_NS`] from now, in the
    /// timer softirq (module documentation). Process context. EBUSY once
    /// the device was moved.
    fn connect(sk: &Sock<Self>, _addr: &[u8], _flags: i32) -> Result {
        let dev = HELD.get(&mut Rtnl::lock()).take().ok_or(EBUSY)?;
        *sk.lock() = Some(dev);
        let job = JobTimers::<Putter>::new(new_irq_spinlock!(Some(sk.to_ref()), "exittest_put")?, sk)?;
        job.get().start(0, ktime_get_mono_ns() as u64 + PUT_AFTER_NS);
        // Forgotten: the module's exit kills it (its memory leaks).
        core::mem::forget(job);
        Ok(())
    }

    fn getname(_sk: &Sock<Self>, _peer: bool, _out: &mut [u8]) -> Result<usize> {
        Err(EOPNOTSUPP())
    }

    fn sendmsg(_sk: &Sock<Self>, _msg: &mut Msg, _len: usize) -> Result<usize> {
        Err(EOPNOTSUPP())
    }

    fn recvmsg(_sk: &Sock<Self>, _msg: &mut Msg, _len: usize, _flags: i32) -> Result<usize> {
        Err(EAGAIN)
    }
}

impl CanProtocol for ExitProto {
    const PROTOCOL: i32 = CANPROTO_EXITTEST;
    const SOCK_TYPE: i32 = SOCK_DGRAM;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// Logs how many open sockets the notifier is shown when a device
    /// goes down (the test compares it with the sockets it holds open).
    /// Process context, RTNL held.
    fn netdev_event(event: NetdevEvent, dev: &NetDev, sockets: &Sockets<'_, Self>) {
        if event != NetdevEvent::Down {
            return;
        }
        let mut n = 0u32;
        sockets.for_each(|_| n += 1);
        pr_info!("{}: down, {} sockets open\n", dev.name(), n);
    }
}

/// The in-kernel receiver: counts frames.
struct CountRx(AtomicU64);

impl KernelRx for CountRx {
    /// NET_RX softirq.
    fn rx(&self, _skb: &Skb, _dev: &NetDev) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
}

static RX: CountRx = CountRx(AtomicU64::new(0));

/// The network device: a CAN device that drops every frame.
pub(crate) struct SinkDev;

impl Driver for SinkDev {
    type Priv = ();

    fn setup() -> Setup {
        ctrl::setup(CAN_MTU, 0)
    }

    /// Process context, RTNL.
    fn open(dev: &Dev<Self>, _p: &()) -> Result {
        dev.start_queue();
        Ok(())
    }

    /// Process context, RTNL.
    fn stop(dev: &Dev<Self>, _p: &()) -> Result {
        dev.stop_queue();
        Ok(())
    }

    /// BH disabled.
    fn start_xmit(skb: Skb, dev: &Dev<Self>, _p: &()) -> Xmit {
        dev.stats_tx_dropped();
        drop(skb);
        Xmit::Ok
    }
}

/// The job: its timer 0 re-arms itself every [`TICK_NS`], counting.
struct Ticker;

impl JobCallback for Ticker {
    type Data = AtomicU64;

    /// HRTIMER_SOFTIRQ.
    fn expired(job: JobRef<'_, Self>, which: usize) {
        job.data().fetch_add(1, Ordering::Relaxed);
        job.start(which, ktime_get_mono_ns() as u64 + TICK_NS);
    }
}

/// The job that drops a socket reference from the timer softirq.
struct Putter;

impl JobCallback for Putter {
    type Data = IrqSpinLock<Option<SockRef<ExitProto>>>;

    /// HRTIMER_SOFTIRQ.
    fn expired(job: JobRef<'_, Self>, _which: usize) {
        let r = job.data().lock().take();
        drop(r);
    }
}

/// The module's value: nothing; everything it registered is forgotten.
pub(crate) struct ExitTest;

impl ScopedModule for ExitTest {
    /// Process context (`insmod`).
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let reg = MODULE.register(c_str!("CANPROTO_EXITTEST"), scope)?;
        *REG.get(&mut Rtnl::lock()) = Some(reg);

        let f = RxFilter {
            kind: RX_FILTER_CAN_ID,
            id: RX_ID,
            mask: 0x7ff,
        };
        core::mem::forget(rx_set_kernel(scope, &RX, 0, &[f])?);

        let dev = Registration::<SinkDev>::register(c_str!("rcanexit%d"), (), scope)?;
        pr_info!("{}: registered, to be forgotten\n", dev.dev().name());
        core::mem::forget(dev);

        let held = Registration::<SinkDev>::register(c_str!("rcanexit%d"), (), scope)?;
        pr_info!("{}: registered, held for a socket\n", held.dev().name());
        *HELD.get(&mut Rtnl::lock()) = Some(held);

        let job = JobTimers::<Ticker>::new(AtomicU64::new(0), scope)?;
        job.get().start(0, ktime_get_mono_ns() as u64 + TICK_NS);
        core::mem::forget(job);

        Ok(ExitTest)
    }
}

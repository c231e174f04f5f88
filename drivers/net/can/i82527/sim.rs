// SPDX-License-Identifier: GPL-2.0

//! rcan_i82527_sim: simulated Intel 82527 cards on one simulated bus.
//! Nothing emulates the 82527 (DESIGN section 3), so this front-end's
//! register accesses go to the register-level model
//! (`rcan_core::i82527_model`, the one the host tests use), and the
//! unchanged driver (`i82527.rs`) runs beneath pf_can and the protocols.
//!
//! The bus: every card's model lives in one array under one spinlock.
//! Writing a transmission request (TxRqst set) to a message object kicks
//! an hrtimer (soft mode); its callback, in softirq context, is the bus
//! and the interrupt wires: it takes one frame from a card whose object
//! wants to send (cards in turn), offers it to every other card's model,
//! then calls the driver's interrupt handler of each card whose
//! interrupt output is raised, and repeats until nothing moves, or re-arms
//! itself after [`FRAMES_PER_RUN`] frames. Frames take no bus time; each
//! frame is in its receivers' queues before the next frame goes out. The
//! callback may run on either CPU from one run to the next; the driver
//! keeps frame order all the same, because its interrupt handler only
//! queues frames (under the chip lock, which is taken with interrupts
//! off) and the device's NAPI poll hands them up in NET_RX softirq, one
//! CPU at a time (see `i82527.rs`). The timer callback calls into the
//! stack only through that poll: never with the bus or a chip lock held.
//!
//! Module parameter `cards` (default 2, at most [`MAX_CARDS`]).
//!
//! Teardown: `DYING` stops the callback from touching anything, the
//! timer is cancelled, the devices are unregistered (their `stop` writes
//! to the models, which no longer kicks), and the timer is cancelled once
//! more before the bus is freed.

use kernel::prelude::*;

#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "i82527.rs"]
mod i82527;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicBool, Ordering};
use glue::bindings;
use glue::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use glue::netdev::Driver;
use glue::params::Param;
use i82527::{add_channel, Channel, I82527};
use rcan_core::i82527::{bits, reg, Config, Regs};
use rcan_core::i82527_model::I82527Model;

module! {
    type: SimModule,
    name: "rcan_i82527_sim",
    author: "rcan developers",
    description: "Simulated Intel 82527 cards on a simulated CAN bus",
    license: "GPL",
}

/// Most simulated cards.
const MAX_CARDS: usize = 8;
/// The model's crystal (for the logged bit rate only).
const XTAL_HZ: u32 = 16_000_000;
/// Frames moved per timer run. The simulated bus has no bit time; a run
/// that moved many frames would queue them all before the NAPI poll (NET_RX
/// softirq) could take any, and overflow the driver's receive queue that a
/// real bus's pace never fills. After this many the timer re-arms and
/// softirqs (NET_RX among them) run in between.
const FRAMES_PER_RUN: usize = 8;
/// Delay of that re-arm, ns: about the time 8 frames take at 1 Mbit/s
/// would be 0.5-1 ms; 20 us keeps the VM tests fast and still yields.
const REARM_NS: i64 = 20_000;
/// Rounds of a run without moving frames (interrupt handling only)
/// before re-arming.
const MAX_ROUNDS: usize = 64;
/// Module parameter `cards` (number 0 in sim_c.c).
const CARDS: Param<u32> = Param::new(0);

extern "C" {
    fn rcan_i82527_sim_lock() -> kernel::ffi::c_ulong;
    fn rcan_i82527_sim_unlock(flags: kernel::ffi::c_ulong);
}

/// The simulated bus: every card's chip.
struct Bus {
    models: [I82527Model; MAX_CARDS],
    n: usize,
    /// The card that sends first in the next round (fairness).
    next: usize,
}

/// The bus under the C-side bus spinlock (`sim_c.c`), shared by every
/// card's register access and the timer.
struct BusLock(UnsafeCell<Bus>);

// SAFETY: the bus is only reached through `lock`, which holds the bus
// spinlock (one bus per module, one lock).
unsafe impl Sync for BusLock {}

impl BusLock {
    /// Takes the bus lock, local interrupts off. Any context.
    fn lock(&self) -> BusGuard<'_> {
        // SAFETY: a static, initialised spinlock (DEFINE_SPINLOCK).
        let flags = unsafe { rcan_i82527_sim_lock() };
        BusGuard {
            bus: self,
            flags,
            _not_send: core::marker::PhantomData,
        }
    }
}

/// The held bus lock.
struct BusGuard<'a> {
    bus: &'a BusLock,
    flags: kernel::ffi::c_ulong,
    _not_send: core::marker::PhantomData<*mut ()>,
}

impl core::ops::Deref for BusGuard<'_> {
    type Target = Bus;
    fn deref(&self) -> &Bus {
        // SAFETY: the bus lock is held while the guard lives.
        unsafe { &*self.bus.0.get() }
    }
}

impl core::ops::DerefMut for BusGuard<'_> {
    fn deref_mut(&mut self) -> &mut Bus {
        // SAFETY: the bus lock is held while the guard lives, exclusively.
        unsafe { &mut *self.bus.0.get() }
    }
}

impl Drop for BusGuard<'_> {
    fn drop(&mut self) {
        // SAFETY: taken in BusLock::lock with these flags, on this CPU
        // (the guard is not Send).
        unsafe { rcan_i82527_sim_unlock(self.flags) };
    }
}

/// Set while the module goes away: no kicks, no callback work.
static DYING: AtomicBool = AtomicBool::new(false);

/// The bus and interrupt timer.
static TIMER: HrTimer<SimBus> = HrTimer::new();

fn kick() {
    if !DYING.load(Ordering::SeqCst) {
        TIMER.start(0);
    }
}

/// Register access of card `idx`: the model behind the bus lock.
struct SimRegs {
    bus: *const BusLock,
    idx: usize,
}

// SAFETY: `bus` points to the module's bus, which outlives every device
// (freed after they are unregistered); access goes through its lock.
unsafe impl Send for SimRegs {}

impl SimRegs {
    fn bus(&self) -> &BusLock {
        // SAFETY: the bus outlives the devices and their register access
        // (see the Send impl).
        unsafe { &*self.bus }
    }
}

impl Regs for SimRegs {
    fn read(&mut self, r: u8) -> u8 {
        self.bus().lock().models[self.idx].read(r)
    }

    fn write(&mut self, r: u8, val: u8) {
        self.bus().lock().models[self.idx].write(r, val);
        // A transmission request: the bus has work.
        let is_ctrl1 = r >= 0x10 && r & 0x0F == reg::CTRL1;
        if is_ctrl1 && (val >> bits::TXRQST) & 0b11 == bits::SET {
            kick();
        }
    }
}

/// What the timer callback works on.
struct SimState {
    bus: *const BusLock,
    devs: [*mut bindings::net_device; MAX_CARDS],
}

// SAFETY: the pointers are the module's bus and registered devices, valid
// until the module's teardown, which stops the callback (DYING, cancel)
// before freeing them.
unsafe impl Send for SimState {}

struct SimBus;

impl HrTimerCallback for SimBus {
    type State = SimState;

    fn run(timer: &'static HrTimer<Self>, st: &mut SimState) {
        if DYING.load(Ordering::SeqCst) {
            return;
        }
        // SAFETY: not DYING, so the bus is alive (SimState's Send impl).
        let bus: &BusLock = unsafe { &*st.bus };
        let mut frames = 0;
        for _ in 0..MAX_ROUNDS {
            if frames == FRAMES_PER_RUN {
                break;
            }
            let mut lines = [false; MAX_CARDS];
            let (n, moved) = {
                let mut b = bus.lock();
                let n = b.n;
                let mut moved = false;
                for k in 0..n {
                    let i = (b.next + k) % n;
                    if let Some(f) = b.models[i].transmit() {
                        for j in (0..n).filter(|&j| j != i) {
                            b.models[j].receive(&f);
                        }
                        b.next = (i + 1) % n;
                        moved = true;
                        break;
                    }
                }
                for (i, l) in lines.iter_mut().enumerate().take(n) {
                    // A bus-off chip whose driver cleared INIT sees the
                    // idle bus it waits for.
                    b.models[i].bus_idle();
                    *l = b.models[i].irq_line();
                }
                (n, moved)
            };
            let mut handled = false;
            for i in (0..n).filter(|&i| lines[i]) {
                // SAFETY: a registered device of this driver, alive while
                // not DYING (above).
                let (d, p) = unsafe { glue::netdev::from_cookie::<I82527<SimRegs>>(st.devs[i]) };
                handled |= <I82527<SimRegs> as Driver>::irq(d, p);
            }
            frames += usize::from(moved);
            if !moved && !handled {
                return;
            }
        }
        // Busy bus: let others (NET_RX) run, come back soon.
        timer.start(REARM_NS);
    }
}

struct SimModule {
    channels: KVec<Channel<SimRegs>>,
    bus: Option<KBox<BusLock>>,
}

impl kernel::Module for SimModule {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        let n = CARDS.get() as usize;
        if n == 0 || n > MAX_CARDS {
            pr_err!("rcan_i82527_sim: cards must be 1..={}\n", MAX_CARDS);
            return Err(EINVAL);
        }
        let bus = KBox::new(
            BusLock(UnsafeCell::new(Bus {
                models: core::array::from_fn(|_| I82527Model::new()),
                n,
                next: 0,
            })),
            GFP_KERNEL,
        )?;
        let bus_ptr: *const BusLock = &*bus;
        let mut m = SimModule {
            channels: KVec::new(),
            bus: Some(bus),
        };
        let mut devs = [core::ptr::null_mut(); MAX_CARDS];
        for (i, d) in devs.iter_mut().enumerate().take(n) {
            let regs = SimRegs {
                bus: bus_ptr,
                idx: i,
            };
            let Some(c) = add_channel(
                regs,
                Config::DEFAULT,
                0,
                XTAL_HZ,
                format_args!("simulated card {i}"),
            )?
            else {
                pr_err!("rcan_i82527_sim: model {} does not probe\n", i);
                return Err(ENODEV);
            };
            *d = c.dev_ptr();
            m.channels.push(c, GFP_KERNEL)?;
        }
        TIMER.init(
            ClockId::Monotonic,
            HrTimerMode::RelativeSoft,
            SimState { bus: bus_ptr, devs },
        )?;
        DYING.store(false, Ordering::SeqCst);
        Ok(m)
    }
}

impl Drop for SimModule {
    fn drop(&mut self) {
        DYING.store(true, Ordering::SeqCst);
        TIMER.cancel();
        // Unregisters the devices (stop, then free).
        drop(core::mem::replace(&mut self.channels, KVec::new()));
        TIMER.cancel();
        if let Some(bus) = self.bus.take() {
            let b = bus.lock();
            for (i, m) in b.models.iter().enumerate().take(b.n) {
                pr_info!(
                    "rcan_i82527_sim: card {}: {} frames sent, {} answered, {} not taken\n",
                    i,
                    m.sent,
                    m.answered,
                    m.not_taken
                );
            }
        }
    }
}

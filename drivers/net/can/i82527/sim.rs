// SPDX-License-Identifier: GPL-2.0

//! rcan_i82527_sim: simulated Intel 82527 cards on one simulated bus.
//! Nothing emulates the 82527 (DESIGN section 3), so this front-end's
//! register accesses go to the register-level model
//! (`rcan_core::i82527_model`, the one the host tests use), and the
//! unchanged driver (`i82527.rs`) runs beneath pf_can and the protocols.
//!
//! The bus: every card's model lives in one array under one spinlock
//! ([`BUS`], a static of the glue's `StaticIrqSpinLock` with a lockdep
//! class of its own), the registered cards in [`CHANNELS`]. Writing a transmission request (TxRqst set) to a message object kicks
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
//! It calls the interrupt handlers under `CHANNELS` (so module exit
//! cannot unregister a card meanwhile); lock order CHANNELS -> chip lock
//! -> BUS.
//!
//! Fault injection (module parameter `fault`, writable at run time under
//! `/sys/module/rcan_i82527_sim/parameters/`, read at each attempt, as
//! `rcan_sja1000_sim`'s): `none`; `noack` (no node acknowledges: an ACK
//! error per attempt, the transmit error counter climbs to error passive,
//! which the 82527 shows as warning, and stays there); `biterr` (a bit 0
//! error per attempt: warning after 12 attempts, bus-off after 32). A
//! failed attempt re-arms the timer after [`RETRY_NS`] (the chip retries
//! by itself).
//!
//! Module parameter `cards` (default 2, at most [`MAX_CARDS`]).
//!
//! Teardown: `DYING` stops the callback from touching anything, the
//! timer is cancelled, the devices are taken out of `CHANNELS` and
//! unregistered (their `stop` writes to the models, which no longer
//! kicks), and the timer is cancelled once more before the bus is taken
//! out of `BUS` and freed. No `unsafe` here: the cards are reached only
//! through the statics, so nothing can outlive what it points to.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, i82527, rcan_core};

use core::sync::atomic::{AtomicBool, Ordering};
use glue::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use glue::lock::StaticIrqSpinLock;
use glue::params::{Param, ParamStr};
use i82527::{add_channel, Channel};
use kernel::c_str;
use rcan_core::i82527::{bits, reg, Config, Regs};
use rcan_core::i82527_model::{Fault, I82527Model, TxAttempt};

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
/// Delay before a failed attempt is retried, ns: bounds the rate of
/// error interrupts on a faulty bus (2 ms: 500 attempts/s per card).
const RETRY_NS: i64 = 2_000_000;
/// Module parameter `cards` (number 0 in sim_c.c).
const CARDS: Param<u32> = Param::new(0);
/// `fault` (string 1).
const FAULT: ParamStr = ParamStr::new(1);

/// The bus fault the parameter names now. Any context (a fixed buffer
/// in sim_c.c, no lock).
fn fault() -> Fault {
    let mut buf = [0u8; 16];
    let n = FAULT.read(&mut buf).min(buf.len() - 1);
    match buf[..n].trim_ascii() {
        b"noack" => Fault::NoAck,
        b"biterr" => Fault::BitErr,
        _ => Fault::None,
    }
}

/// The simulated bus: every card's chip.
struct Bus {
    models: [I82527Model; MAX_CARDS],
    n: usize,
    /// The card that sends first in the next round (fairness).
    next: usize,
}

/// The bus, shared by every card's register access and the timer; `None`
/// outside the module's lifetime. Taken inside a card's chip lock (the
/// driver reads registers under it), never the other way round.
static BUS: StaticIrqSpinLock<Option<KBox<Bus>>> =
    StaticIrqSpinLock::new(None, c_str!("rcan_i82527_sim::BUS"));

/// The registered cards, in bus order, for the timer's interrupt
/// delivery; empty outside the module's lifetime. Lock order: CHANNELS ->
/// a card's chip lock -> BUS.
static CHANNELS: StaticIrqSpinLock<KVec<Channel<SimRegs>>> =
    StaticIrqSpinLock::new(KVec::new(), c_str!("rcan_i82527_sim::CHANNELS"));

/// Set while the module goes away: no kicks, no callback work.
static DYING: AtomicBool = AtomicBool::new(false);

/// The bus and interrupt timer.
static TIMER: HrTimer<SimBus> = HrTimer::new();

fn kick() {
    if !DYING.load(Ordering::SeqCst) {
        TIMER.start(0);
    }
}

/// Register access of card `idx`: its model on the bus.
struct SimRegs {
    idx: usize,
}

impl Regs for SimRegs {
    fn read(&mut self, r: u8) -> u8 {
        match BUS.lock().as_mut() {
            Some(b) => b.models[self.idx].read(r),
            // No bus: as an absent chip.
            None => 0xFF,
        }
    }

    fn write(&mut self, r: u8, val: u8) {
        if let Some(b) = BUS.lock().as_mut() {
            b.models[self.idx].write(r, val);
        }
        // A transmission request: the bus has work.
        let is_ctrl1 = r >= 0x10 && r & 0x0F == reg::CTRL1;
        if is_ctrl1 && (val >> bits::TXRQST) & 0b11 == bits::SET {
            kick();
        }
    }
}

struct SimBus;

impl HrTimerCallback for SimBus {
    type State = ();

    fn run(timer: &'static HrTimer<Self>, _st: &mut ()) {
        if DYING.load(Ordering::SeqCst) {
            return;
        }
        let fault = fault();
        let mut frames = 0;
        for _ in 0..MAX_ROUNDS {
            if frames == FRAMES_PER_RUN {
                break;
            }
            let mut lines = [false; MAX_CARDS];
            let (n, moved, failed) = {
                let mut g = BUS.lock();
                let Some(b) = g.as_mut() else {
                    return;
                };
                let n = b.n;
                let (mut moved, mut failed) = (false, false);
                for k in 0..n {
                    let i = (b.next + k) % n;
                    match b.models[i].attempt(fault) {
                        TxAttempt::Sent(f) => {
                            for j in (0..n).filter(|&j| j != i) {
                                b.models[j].receive(&f);
                            }
                            moved = true;
                        }
                        TxAttempt::Failed => failed = true,
                        TxAttempt::Idle => continue,
                    }
                    b.next = (i + 1) % n;
                    break;
                }
                for (i, l) in lines.iter_mut().enumerate().take(n) {
                    // A bus-off chip whose driver cleared INIT sees the
                    // idle bus it waits for.
                    b.models[i].bus_idle();
                    *l = b.models[i].irq_line();
                }
                (n, moved, failed)
            };
            // The bus lock is released: the handlers take their chip lock
            // and then the bus lock for each register access.
            let mut handled = false;
            {
                let chans = CHANNELS.lock();
                for (i, c) in chans.iter().enumerate().take(n) {
                    if lines[i] {
                        handled |= c.irq();
                    }
                }
            }
            if failed {
                // The chip retries by itself, a little later.
                timer.start(RETRY_NS);
                return;
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

/// The module: its state is in the statics above, torn down in Drop.
pub(crate) struct SimModule;

impl kernel::Module for SimModule {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        let n = CARDS.get() as usize;
        if n == 0 || n > MAX_CARDS {
            pr_err!("rcan_i82527_sim: cards must be 1..={}\n", MAX_CARDS);
            return Err(EINVAL);
        }
        let bus = KBox::new(
            Bus {
                models: core::array::from_fn(|_| I82527Model::new()),
                n,
                next: 0,
            },
            GFP_KERNEL,
        )?;
        // From here on a failure tears down through Drop (after `chans`,
        // declared later, has unregistered what it holds).
        let m = SimModule;
        *BUS.lock() = Some(bus);
        let mut chans = KVec::with_capacity(n, GFP_KERNEL)?;
        for i in 0..n {
            let Some(c) = add_channel(
                SimRegs { idx: i },
                Config::DEFAULT,
                0,
                XTAL_HZ,
                format_args!("simulated card {i}"),
            )?
            else {
                pr_err!("rcan_i82527_sim: model {} does not probe\n", i);
                return Err(ENODEV);
            };
            chans.push(c, GFP_KERNEL)?;
        }
        // The old (empty) vector is dropped with the guard held: it owns
        // no memory.
        *CHANNELS.lock() = chans;
        TIMER.init(ClockId::Monotonic, HrTimerMode::RelativeSoft, ())?;
        DYING.store(false, Ordering::SeqCst);
        Ok(m)
    }
}

impl Drop for SimModule {
    fn drop(&mut self) {
        DYING.store(true, Ordering::SeqCst);
        TIMER.cancel();
        // Unregisters the devices (stop, then free), outside the lock.
        let chans = core::mem::replace(&mut *CHANNELS.lock(), KVec::new());
        drop(chans);
        TIMER.cancel();
        let Some(bus) = BUS.lock().take() else {
            return;
        };
        for (i, m) in bus.models.iter().enumerate().take(bus.n) {
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

// SPDX-License-Identifier: GPL-2.0

//! rcan_sja1000_sim: simulated SJA1000 cards on one simulated bus, with
//! fault injection. QEMU's SJA1000 cards never produce bus errors (DESIGN
//! section 3), so this front-end's register accesses go to the
//! register-level model (`rcan_core::sja1000_model`, the one the host
//! tests use), and the unchanged SJA1000 driver (`sja1000.rs`) runs
//! beneath pf_can and the protocols, with error frames, error states,
//! bus-off and restarts that user space sees as on real hardware.
//!
//! The bus: every card's model lives in one array under one spinlock
//! ([`BUS`], a static `StaticIrqSpinLock` with a lockdep class of its
//! own), the registered cards in [`CHANNELS`]. A transmission request
//! (CMR.TR) kicks an hrtimer (soft mode); its callback, in softirq
//! context, is the bus and the interrupt wires: it lets one card with a
//! pending frame (cards in turn) make one attempt under the fault the
//! module parameters name, offers a frame that went out to every other
//! card's model, then calls the driver's interrupt handler of each card
//! whose interrupt output is raised, and repeats until nothing moves
//! ([`FRAMES_PER_RUN`] frames at most per run, then it re-arms). A failed
//! attempt (the chip retries by itself) re-arms the timer after
//! [`RETRY_NS`], so a card that nobody acknowledges retries at a bounded
//! rate. Frames take no bus time. Lock order: CHANNELS -> a card's chip
//! lock -> BUS (the driver reads registers under its chip lock); the
//! callback calls the interrupt handlers with only CHANNELS held.
//!
//! Fault injection (module parameters, writable at run time under
//! `/sys/module/rcan_sja1000_sim/parameters/`; read at each attempt):
//!
//! * `fault`: `none`; `noack` (no node acknowledges: the transmitter's
//!   counter climbs by 8 per attempt to error passive and stays there);
//!   `biterr` (every attempt ends in a bus error with ECC `fault_ecc`,
//!   default a bit error in the data field: error warning after 12
//!   attempts, passive after 16, bus-off after 32); `arblost` (each frame
//!   loses arbitration once, at bit `fault_bit`, then goes out);
//!   `overrun` (each frame on the bus arrives at the receivers until
//!   their FIFO overflows).
//! * A card alone on the bus (the others down or listen-only) gets no
//!   acknowledgement either, as on a real bus, unless it runs with
//!   `presume-ack on`.
//!
//! Module parameter `cards` (default 2, at most [`MAX_CARDS`]).
//!
//! Teardown as `rcan_i82527_sim`: `DYING` stops the callback, the timer
//! is cancelled, the devices are unregistered, the timer is cancelled
//! again before the bus is freed. No `unsafe` here.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, rcan_core, sja1000};

use core::sync::atomic::{AtomicBool, Ordering};
use glue::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use glue::lock::StaticIrqSpinLock;
use glue::params::{Param, ParamStr};
use kernel::c_str;
use rcan_core::sja1000::{cmd, reg, Regs, CDR_CBP, CDR_CLK_OFF};
use rcan_core::sja1000_model::{ecc, Fault, Sja1000Model, TxAttempt};
use sja1000::{add_channel, module_config, Channel};

/// Most simulated cards.
const MAX_CARDS: usize = 8;
/// The model's crystal (as the PCI boards: 16 MHz, an 8 MHz CAN clock).
const XTAL_HZ: u32 = 16_000_000;
/// Frames moved per timer run before re-arming (softirqs, NET_RX among
/// them, run in between).
const FRAMES_PER_RUN: usize = 8;
/// Delay of that re-arm, ns.
const REARM_NS: i64 = 20_000;
/// Delay before a failed attempt is retried, ns: bounds the rate of
/// error interrupts on a faulty bus (2 ms: 500 attempts/s per card).
const RETRY_NS: i64 = 2_000_000;
/// Rounds of a run before re-arming.
const MAX_ROUNDS: usize = 64;
/// Most deliveries of one frame to one card under the `overrun` fault.
const OVERRUN_COPIES: usize = 32;
/// Output control as on the Kvaser PCIcan (normal mode, push-pull).
const OCR: u8 = 0xDA;

/// Module parameter `cards` (number 2 in sim_c.c; 0 and 1 are the SJA1000
/// core's `btr0`/`btr1`).
const CARDS: Param<u32> = Param::new(2);
/// `fault_ecc` (3): the ECC of `biterr`; -1: [`ecc::TX_BIT_DATA`].
const FAULT_ECC: Param<i32> = Param::new(3);
/// `fault_bit` (4): where `arblost` loses arbitration.
const FAULT_BIT: Param<u32> = Param::new(4);
/// `fault` (string 5).
const FAULT: ParamStr = ParamStr::new(5);

/// The bus condition the parameters name now. Any context.
fn fault() -> (Fault, bool) {
    let mut buf = [0u8; 16];
    let n = FAULT.read(&mut buf).min(buf.len() - 1);
    let name = buf[..n].trim_ascii();
    match name {
        b"noack" => (Fault::NoAck, false),
        b"biterr" => {
            let e = FAULT_ECC.get();
            let ecc = u8::try_from(e).unwrap_or(ecc::TX_BIT_DATA);
            (Fault::BusError { ecc }, false)
        }
        b"arblost" => (
            Fault::ArbitrationLost {
                bit: (FAULT_BIT.get() & 0x1F) as u8,
            },
            false,
        ),
        b"overrun" => (Fault::None, true),
        _ => (Fault::None, false),
    }
}

/// The simulated bus: every card's chip.
struct Bus {
    models: [Sja1000Model; MAX_CARDS],
    n: usize,
    /// The card that sends first in the next round (fairness).
    next: usize,
}

/// The bus, shared by every card's register access and the timer; `None`
/// outside the module's lifetime. Taken inside a card's chip lock, never
/// the other way round.
static BUS: StaticIrqSpinLock<Option<KBox<Bus>>> =
    StaticIrqSpinLock::new(None, c_str!("rcan_sja1000_sim::BUS"));

/// The registered cards, in bus order, for the timer's interrupt
/// delivery; empty outside the module's lifetime. Lock order: CHANNELS ->
/// a card's chip lock -> BUS.
static CHANNELS: StaticIrqSpinLock<KVec<Channel<SimRegs>>> =
    StaticIrqSpinLock::new(KVec::new(), c_str!("rcan_sja1000_sim::CHANNELS"));

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
        if r == reg::CMR && val & (cmd::TR | cmd::SRR) != 0 {
            kick();
        }
    }
}

/// What one round of the bus did.
struct Round {
    moved: bool,
    failed: bool,
}

/// One round on the bus: one attempt by the first card (in turn) with a
/// frame pending. Bus lock held.
fn round(b: &mut Bus, fault: Fault, overrun: bool) -> Round {
    let n = b.n;
    let mut r = Round {
        moved: false,
        failed: false,
    };
    for k in 0..n {
        let i = (b.next + k) % n;
        if !b.models[i].tx_pending {
            continue;
        }
        let acked = (0..n).any(|j| j != i && b.models[j].acks());
        match b.models[i].transmit(fault, acked) {
            TxAttempt::Sent(f) => {
                for j in (0..n).filter(|&j| j != i) {
                    let copies = if overrun { OVERRUN_COPIES } else { 1 };
                    for _ in 0..copies {
                        if !b.models[j].deliver(&f) {
                            break;
                        }
                    }
                }
                b.next = (i + 1) % n;
                r.moved = true;
            }
            TxAttempt::Failed => {
                b.next = (i + 1) % n;
                r.failed = true;
            }
            TxAttempt::Idle => continue,
        }
        break;
    }
    r
}

struct SimBus;

impl HrTimerCallback for SimBus {
    type State = ();

    /// HRTIMER_SOFTIRQ softirq context.
    fn run(timer: &'static HrTimer<Self>, _st: &mut ()) {
        if DYING.load(Ordering::SeqCst) {
            return;
        }
        let (fault, overrun) = fault();
        let mut frames = 0;
        for _ in 0..MAX_ROUNDS {
            if frames == FRAMES_PER_RUN {
                break;
            }
            let mut lines = [false; MAX_CARDS];
            let (n, r) = {
                let mut g = BUS.lock();
                let Some(b) = g.as_mut() else {
                    return;
                };
                let r = round(b, fault, overrun);
                for (i, l) in lines.iter_mut().enumerate().take(b.n) {
                    *l = b.models[i].irq_pending();
                }
                (b.n, r)
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
            if r.failed {
                // The chip retries by itself, a little later.
                timer.start(RETRY_NS);
                return;
            }
            frames += usize::from(r.moved);
            if !r.moved && !handled {
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
            pr_err!("rcan_sja1000_sim: cards must be 1..={}\n", MAX_CARDS);
            return Err(EINVAL);
        }
        let bus = KBox::new(
            Bus {
                models: core::array::from_fn(|_| Sja1000Model::new()),
                n,
                next: 0,
            },
            GFP_KERNEL,
        )?;
        // From here on a failure tears down through Drop (after `chans`,
        // declared later, has unregistered what it holds).
        let m = SimModule;
        *BUS.lock() = Some(bus);
        TIMER.init(ClockId::Monotonic, HrTimerMode::RelativeSoft, ())?;
        DYING.store(false, Ordering::SeqCst);
        let mut chans = KVec::with_capacity(n, GFP_KERNEL)?;
        for i in 0..n {
            let Some(c) = add_channel(
                SimRegs { idx: i },
                module_config(OCR, CDR_CBP | CDR_CLK_OFF),
                0,
                XTAL_HZ,
                format_args!("simulated card {i}"),
            )?
            else {
                pr_err!("rcan_sja1000_sim: model {} does not probe\n", i);
                return Err(ENODEV);
            };
            chans.push(c, GFP_KERNEL)?;
        }
        // The old (empty) vector is dropped with the guard held: it owns
        // no memory.
        *CHANNELS.lock() = chans;
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
                "rcan_sja1000_sim: card {}: {} frames sent, {} attempts failed\n",
                i,
                m.sent,
                m.tx_failed
            );
        }
    }
}

// SPDX-License-Identifier: GPL-2.0

//! rcan_i82527_sim: simulated Intel 82527 cards on one simulated bus.
//! Nothing emulates the 82527 (DESIGN section 3), so this front-end's
//! register accesses go to the register-level model
//! (`crate::rcan_chips::i82527_model`, the one the host tests use), and the
//! unchanged driver (`i82527.rs`) runs beneath pf_can and the protocols.
//!
//! The bus, its timer and teardown are the glue's simulated-card
//! scaffolding ([`glue::simcard`], shared with `rcan_sja1000_sim`): every
//! card's model lives in one [`Bus`] under the bus lock (lockdep class
//! `rcan_i82527_sim::BUS`), the registered cards under
//! `rcan_i82527_sim::CHANNELS`. Writing a transmission request (TxRqst
//! set) to a message object kicks an hrtimer (soft mode); its callback,
//! in softirq context, is the bus and the interrupt wires: it takes one
//! frame from a card whose object wants to send (cards in turn), offers
//! it to every other card's model, then calls the driver's interrupt
//! handler of each card whose interrupt output is raised, and repeats
//! until nothing moves. A frame takes its bus time: the bits of the frame
//! (without stuff bits, with the intermission) at the bit timing the
//! sender's BT0/BT1 program (`ip link set canX type can bitrate ...`),
//! and the bus runs its next round only when that time has passed
//! ([`glue::simcard`]'s pacing; a late timer catches up by at most
//! [`glue::simcard::LATE_NS`]). So a burst goes at most at the bit rate
//! (500 kbit/s by default: some 4,000 frames/s), as on a real bus, and
//! the simulated interrupt, which may run on a CPU other than the one
//! that owns the device's NAPI poll, cannot queue frames faster than
//! that. Each frame is in its receivers' queues (or, while a driver has
//! no room there, still in its chip) before the next frame goes out.
//! The bus does not overrun a receive object either: a frame
//! whose receiver still holds an unread frame in its way (the object it
//! would go to, or one the host would read after it:
//! `I82527Model::ready_for`) stays pending in the sender's object, the
//! bus idle, until that host reads (its write to the object's control
//! register kicks the bus; see `sim_bus` and [`glue::simcard`]). A real
//! 82527 would acknowledge it and overwrite the object (MsgLst), but a
//! real host reads within a frame time, while this bus runs from a timer
//! on one virtual CPU and the receiving driver's NAPI poll may be on
//! another that the host machine does not schedule for longer than the
//! driver's queue lasts (the driver then turns its chip's interrupt
//! output off and leaves the frames in the chip, `i82527.rs`). So no
//! frame is lost or reordered that a host keeping up with a real bus
//! would have received; `fault=overrun` still overruns on purpose. The
//! callback may run on either CPU from one run to
//! the next; the driver keeps frame order all the same, because its
//! interrupt handler only queues frames (under the chip lock, which is
//! taken with interrupts off) and the device's NAPI poll hands them up in
//! NET_RX softirq, one CPU at a time (see `i82527.rs`). The timer
//! callback calls into the stack only through that poll: never with the
//! bus or a chip lock held. It calls the interrupt handlers under the
//! cards lock (so module exit cannot unregister a card meanwhile); lock
//! order CHANNELS -> chip lock -> BUS.
//!
//! Fault injection (module parameter `fault`, writable at run time under
//! `/sys/module/rcan_i82527_sim/parameters/`, read at each attempt, as
//! `rcan_sja1000_sim`'s): `none`; `noack` (no node acknowledges: an ACK
//! error per attempt, the transmit error counter climbs to error passive,
//! which the 82527 shows as warning, and stays there); `biterr` (a bit 0
//! error per attempt: warning after 12 attempts, bus-off after 32);
//! `overrun` (every frame reaches the other cards twice before their
//! driver can read the first, so the receive object overflows: MsgLst,
//! an overrun error frame and `rx_over_errors` on the receiver). A
//! failed attempt re-arms the timer after [`glue::simcard::RETRY_NS`] (the chip
//! retries by itself).
//!
//! Module parameter `cards` (default 2, at most [`glue::simcard::MAX_CARDS`]).
//!
//! Teardown ([`SimCards::stop`]): no more timer work, the devices
//! unregistered (their `stop` writes to the models, which no longer
//! kicks), then the bus freed. No `unsafe` here: the cards are reached
//! only through the static [`SIM`], so nothing can outlive what it points
//! to.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, i82527};

use crate::rcan_chips::i82527::{bits, ctrl, reg, Config, Regs};
use crate::rcan_chips::i82527_model::{Fault, I82527Model};
use crate::rcan_chips::sim_bus::{self, Outcome};
use glue::params::{Param, ParamStr};
use glue::simcard::{self, param_word, Round, SimBus, SimCards, FAULT_LEN, MAX_CARDS};
use i82527::{add_channel, Channel};
use glue::module::ModuleScope;
use kernel::c_str;

/// The model's crystal (the logged bit rate, a frame's bus time).
const XTAL_HZ: u32 = 16_000_000;
/// Module parameter `cards` (number 0 in sim_c.c).
const CARDS: Param<u32> = Param::new(0);
/// `fault` (string 1).
const FAULT: ParamStr = ParamStr::new(1);

/// The simulated bus: every card's chip.
pub(crate) struct Bus {
    models: [I82527Model; MAX_CARDS],
    n: usize,
    /// The card that sends first in the next round (fairness).
    next: usize,
    /// Bus time of the frame the last round sent, ns.
    last_ns: i64,
}

/// The bus and the registered cards (see [`glue::simcard`]).
static SIM: SimCards<Bus> = SimCards::new(
    c_str!("rcan_i82527_sim::BUS"),
    c_str!("rcan_i82527_sim::CHANNELS"),
);

impl SimBus for Bus {
    const NAME: &'static str = "rcan_i82527_sim";
    type Card = Channel<SimRegs>;
    type Fault = Fault;

    fn sim() -> &'static SimCards<Self> {
        &SIM
    }

    fn cards_param() -> usize {
        CARDS.get() as usize
    }

    fn add_card(scope: &ModuleScope, i: usize) -> Result<Option<Channel<SimRegs>>> {
        add_channel(
            scope,
            SimRegs { idx: i },
            Config::DEFAULT,
            0,
            XTAL_HZ,
            format_args!("simulated card {i}"),
        )
    }

    fn new(n: usize) -> Self {
        Bus {
            models: core::array::from_fn(|_| I82527Model::new()),
            n,
            next: 0,
            last_ns: 0,
        }
    }

    fn cards(&self) -> usize {
        self.n
    }

    /// The bus fault the parameter names now. Any context (a fixed
    /// buffer in sim_c.c, no lock).
    fn fault() -> Fault {
        match param_word(&FAULT, &mut [0u8; FAULT_LEN]) {
            b"noack" => Fault::NoAck,
            b"biterr" => Fault::BitErr,
            b"overrun" => Fault::Overrun,
            _ => Fault::None,
        }
    }

    /// One attempt by the first card (in turn) with a frame pending;
    /// under `overrun` the others receive it twice before their driver
    /// runs.
    fn round(&mut self, fault: Fault) -> Round {
        let copies = if fault == Fault::Overrun { 2 } else { 1 };
        let models = &mut self.models[..self.n];
        let out = sim_bus::round(models, &mut self.next, fault, copies);
        if let Outcome::Sent(i, f) = out {
            let ns = self.models[i].frame_ns(&f, XTAL_HZ);
            self.last_ns = i64::try_from(ns).unwrap_or(0);
        }
        Round {
            moved: out.moved(),
            failed: out.failed(),
            held: out.held(),
        }
    }

    fn irq_line(&mut self, i: usize) -> bool {
        // A bus-off chip whose driver cleared INIT sees the idle bus it
        // waits for.
        self.models[i].bus_idle();
        self.models[i].irq_line()
    }

    fn read(&mut self, i: usize, r: u8) -> u8 {
        self.models[i].read(r)
    }

    fn write(&mut self, i: usize, r: u8, val: u8) {
        self.models[i].write(r, val);
    }

    /// TxRqst set in a message object's control register 1.
    fn is_tx_request(r: u8, val: u8) -> bool {
        let is_ctrl1 = r >= 0x10 && r & 0x0F == reg::CTRL1;
        is_ctrl1 && (val >> bits::TXRQST) & 0b11 == bits::SET
    }

    /// A write to a message object's control registers: the host resets
    /// IntPnd and NewDat there when it reads a receive object.
    fn frees_rx(r: u8, _val: u8) -> bool {
        r >= 0x10 && (r & 0x0F == reg::CTRL0 || r & 0x0F == reg::CTRL1)
    }

    /// IE set in the control register (the driver turning its interrupt
    /// output back on once it has room again, or starting the chip).
    fn enables_irq(r: u8, val: u8) -> bool {
        r == reg::CONTROL && val & ctrl::IE != 0
    }

    fn card_irq(c: &Channel<SimRegs>) -> bool {
        c.irq()
    }

    fn bus_ns(&self) -> i64 {
        self.last_ns
    }

    fn report(&self) {
        for (i, m) in self.models.iter().enumerate().take(self.n) {
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

/// Register access of card `idx`: its model on the bus.
pub(crate) struct SimRegs {
    idx: usize,
}

impl Regs for SimRegs {
    fn read(&mut self, r: u8) -> u8 {
        SIM.read(self.idx, r)
    }

    fn write(&mut self, r: u8, val: u8) {
        SIM.write(self.idx, r, val);
    }
}

/// The module: its state is in [`SIM`], set up and torn down by the glue.
pub(crate) type SimModule = glue::module::Scoped<simcard::SimModule<Bus>>;

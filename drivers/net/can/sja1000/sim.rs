// SPDX-License-Identifier: GPL-2.0

//! rcan_sja1000_sim: simulated SJA1000 cards on one simulated bus, with
//! fault injection. QEMU's SJA1000 cards never produce bus errors (DESIGN
//! section 3), so this front-end's register accesses go to the
//! register-level model (`crate::rcan_chips::sja1000_model`, the one the host
//! tests use), and the unchanged SJA1000 driver (`sja1000.rs`) runs
//! beneath pf_can and the protocols, with error frames, error states,
//! bus-off and restarts that user space sees as on real hardware.
//!
//! The bus, its timer and teardown are the glue's simulated-card
//! scaffolding ([`glue::simcard`], shared with `rcan_i82527_sim`): every
//! card's model lives in one [`Bus`] under the bus lock (lockdep class
//! `rcan_sja1000_sim::BUS`), the registered cards under
//! `rcan_sja1000_sim::CHANNELS`. A transmission request (CMR.TR) kicks
//! an hrtimer (soft mode); its callback, in softirq context, is the bus
//! and the interrupt wires: it lets one card with a pending frame (cards
//! in turn) make one attempt under the fault the module parameters name,
//! offers a frame that went out to every other card's model, then calls
//! the driver's interrupt handler of each card whose interrupt output is
//! raised, and repeats until nothing moves (a few frames at most per run,
//! then it re-arms). A failed attempt (the chip retries by itself)
//! re-arms the timer after [`glue::simcard::RETRY_NS`], so a card that nobody
//! acknowledges retries at a bounded rate. Frames take no bus time. Lock
//! order: CHANNELS -> a card's chip lock -> BUS (the driver reads
//! registers under its chip lock); the callback calls the interrupt
//! handlers with only CHANNELS held.
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
//! Module parameter `cards` (default 2, at most [`glue::simcard::MAX_CARDS`]).
//!
//! Teardown as `rcan_i82527_sim` ([`SimCards::stop`]): no more timer
//! work, the devices unregistered, then the bus freed. No `unsafe` here.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, sja1000};

use crate::rcan_chips::sim_bus;
use crate::rcan_chips::sja1000::{cmd, reg, Regs, CDR_CBP, CDR_CLK_OFF};
use crate::rcan_chips::sja1000_model::{ecc, Fault, Sja1000Model};
use glue::params::{Param, ParamStr};
use glue::simcard::{self, param_word, Round, SimBus, SimCards, FAULT_LEN, MAX_CARDS};
use glue::module::ModuleScope;
use kernel::c_str;
use sja1000::{add_channel, module_config, Channel};

/// The model's crystal (as the PCI boards: 16 MHz, an 8 MHz CAN clock).
const XTAL_HZ: u32 = 16_000_000;
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

/// The simulated bus: every card's chip.
pub(crate) struct Bus {
    models: [Sja1000Model; MAX_CARDS],
    n: usize,
    /// The card that sends first in the next round (fairness).
    next: usize,
}

/// The bus and the registered cards (see [`glue::simcard`]).
static SIM: SimCards<Bus> = SimCards::new(
    c_str!("rcan_sja1000_sim::BUS"),
    c_str!("rcan_sja1000_sim::CHANNELS"),
);

impl SimBus for Bus {
    const NAME: &'static str = "rcan_sja1000_sim";
    type Card = Channel<SimRegs>;
    /// The fault, and whether frames overrun the receivers (`overrun`).
    type Fault = (Fault, bool);

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
            module_config(OCR, CDR_CBP | CDR_CLK_OFF),
            0,
            XTAL_HZ,
            format_args!("simulated card {i}"),
        )
    }

    fn new(n: usize) -> Self {
        Bus {
            models: core::array::from_fn(|_| Sja1000Model::new()),
            n,
            next: 0,
        }
    }

    fn cards(&self) -> usize {
        self.n
    }

    /// The bus condition the parameters name now. Any context.
    fn fault() -> (Fault, bool) {
        match param_word(&FAULT, &mut [0u8; FAULT_LEN]) {
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

    /// One attempt by the first card (in turn) with a frame pending.
    fn round(&mut self, (fault, overrun): (Fault, bool)) -> Round {
        let copies = if overrun { OVERRUN_COPIES } else { 1 };
        let out = sim_bus::round(&mut self.models[..self.n], &mut self.next, fault, copies);
        Round {
            moved: out.moved(),
            failed: out.failed(),
            held: out.held(),
        }
    }

    fn irq_line(&mut self, i: usize) -> bool {
        self.models[i].irq_pending()
    }

    fn read(&mut self, i: usize, r: u8) -> u8 {
        self.models[i].read(r)
    }

    fn write(&mut self, i: usize, r: u8, val: u8) {
        self.models[i].write(r, val);
    }

    /// CMR.TR or CMR.SRR.
    fn is_tx_request(r: u8, val: u8) -> bool {
        r == reg::CMR && val & (cmd::TR | cmd::SRR) != 0
    }

    fn card_irq(c: &Channel<SimRegs>) -> bool {
        c.irq()
    }

    fn report(&self) {
        for (i, m) in self.models.iter().enumerate().take(self.n) {
            pr_info!(
                "rcan_sja1000_sim: card {}: {} frames sent, {} attempts failed\n",
                i,
                m.sent,
                m.tx_failed
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

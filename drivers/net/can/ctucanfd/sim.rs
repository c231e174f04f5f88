// SPDX-License-Identifier: GPL-2.0

//! rcan_ctucanfd_sim: simulated CTU CAN FD cores on one simulated bus,
//! with fault injection. QEMU's `ctucan_pci` has no fault confinement
//! (FAULT_STATE and the error counters read 0, no error interrupt but
//! the data overrun), so this front-end's register accesses go to the
//! register-level model (`crate::rcan_chips::ctucanfd_model`, the one the
//! host tests use, with fault confinement as the datasheet describes
//! it), and the unchanged CTU CAN FD driver (`ctucanfd.rs`) runs beneath
//! pf_can and the protocols, with error frames, error states, bus-off
//! and restarts that user space sees as on real hardware.
//!
//! The bus, its timer and teardown are the glue's simulated-card
//! scaffolding ([`glue::simcard`], shared with `rcan_sja1000_sim` and
//! `rcan_i82527_sim`): every core's model lives in one [`Bus`] under the
//! bus lock (lockdep class `rcan_ctucanfd_sim::BUS`), the registered
//! cores under `rcan_ctucanfd_sim::CHANNELS`. The driver's 32-bit
//! register accesses reach the models through
//! [`SimCards::with_bus`](glue::simcard::SimCards::with_bus); a
//! TX_COMMAND write that marks a buffer ready (TXCR) kicks the bus's
//! hrtimer (soft mode). Its callback, in softirq context, is the bus and
//! the interrupt wires: it lets one core with a ready TX buffer (cores in
//! turn) make one attempt under the fault the module parameters name,
//! offers a frame that went out to every other core's model, then calls
//! the driver's interrupt handler of each core whose interrupt output is
//! raised, and repeats until nothing moves (a few frames at most per run,
//! then it re-arms). A failed attempt (the core retries by itself)
//! re-arms the timer after [`glue::simcard::RETRY_NS`]. Frames take no
//! bus time. Lock order: CHANNELS -> a core's chip lock -> BUS (the
//! driver reads registers under its chip lock); the callback calls the
//! interrupt handlers with only CHANNELS held.
//!
//! Fault injection (module parameters, writable at run time under
//! `/sys/module/rcan_ctucanfd_sim/parameters/`; read at each attempt):
//!
//! * `fault`: `none`; `noack` (no node acknowledges: the transmitter's
//!   TEC climbs by 8 per attempt to error passive and stays there);
//!   `biterr` (every attempt ends in a bus error whose ERR_CAPT byte is
//!   `fault_capt`, default a bit error in the data field: error warning
//!   after 12 attempts, passive after 16, bus-off after 32); `arblost`
//!   (each frame loses arbitration once, at bit `fault_bit`, then goes
//!   out); `overrun` (each frame on the bus arrives at the receivers
//!   again and again until their RX buffer overflows).
//! * A core alone on the bus (the others down or listen-only) gets no
//!   acknowledgement either, as on a real bus, unless it runs with
//!   `presume-ack on`.
//!
//! Module parameter `cards` (default 2, at most
//! [`glue::simcard::MAX_CARDS`]). Each simulated core has an RX buffer of
//! [`RX_WORDS`] words (a synthesis parameter of the real core; QEMU's
//! has 2048) and four TX buffers, and runs at 100 MHz as the PCI card's.
//!
//! Teardown as the other simulated cards ([`glue::simcard::SimCards::stop`]):
//! no more timer work, the devices unregistered, then the bus freed. No
//! `unsafe` here.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{ctucanfd, glue};

use crate::rcan_chips::ctucanfd::{reg, txcmd, Regs};
use crate::rcan_chips::ctucanfd_model::{err_capt, err_pos, err_type, CtuModel, Fault};
use crate::rcan_chips::sim_bus;
use crate::rcan_core::candev::Settings;
use ctucanfd::{add_core, Core};
use glue::params::{Param, ParamStr};
use glue::simcard::{self, param_word, Round, SimBus, SimCards, FAULT_LEN};
use glue::module::ModuleScope;
use kernel::c_str;

/// Words of each simulated core's RX buffer (1 KiB: 42 classic frames
/// of 8 bytes, 14 FD frames of 64). The model is built on the stack
/// before it moves to the heap, so it is kept small.
pub(crate) const RX_WORDS: usize = 256;
/// The core clock (as on the PCI card).
const CLOCK_HZ: u32 = 100_000_000;
/// Most deliveries of one frame to one core under the `overrun` fault:
/// one more than its RX buffer holds of the smallest frame (4 words), so
/// each frame overruns an empty buffer once.
const OVERRUN_COPIES: usize = RX_WORDS / 4 + 1;

/// Module parameter `cards` (number 0 in sim_c.c).
const CARDS: Param<u32> = Param::new(0);
/// `fault_capt` (1): the ERR_CAPT byte of `biterr`; -1: a bit error in
/// the data field.
const FAULT_CAPT: Param<i32> = Param::new(1);
/// `fault_bit` (2): where `arblost` loses arbitration.
const FAULT_BIT: Param<u32> = Param::new(2);
/// `fault` (string 3).
const FAULT: ParamStr = ParamStr::new(3);

/// One simulated core.
type Model = CtuModel<RX_WORDS>;

/// The simulated bus: every core's model.
pub(crate) struct Bus {
    /// The cores, in bus order (allocated by [`SimBus::alloc`]).
    models: KVec<Model>,
    /// The core that sends first in the next round (fairness).
    next: usize,
}

/// The bus and the registered cores (see [`glue::simcard`]).
static SIM: SimCards<Bus> = SimCards::new(
    c_str!("rcan_ctucanfd_sim::BUS"),
    c_str!("rcan_ctucanfd_sim::CHANNELS"),
);

impl SimBus for Bus {
    const NAME: &'static str = "rcan_ctucanfd_sim";
    type Card = Core<SimRegs>;
    /// The fault, and whether frames overrun the receivers (`overrun`).
    type Fault = (Fault, bool);

    fn sim() -> &'static SimCards<Self> {
        &SIM
    }

    fn cards_param() -> usize {
        CARDS.get() as usize
    }

    fn add_card(scope: &ModuleScope, i: usize) -> Result<Option<Core<SimRegs>>> {
        add_core(
            scope,
            SimRegs { idx: i },
            0,
            CLOCK_HZ,
            Settings::default(),
            format_args!("simulated core {i}"),
        )
    }

    /// A bus without cores: [`SimBus::alloc`] (what module init calls)
    /// adds them on the heap.
    fn new(_cards: usize) -> Self {
        Bus {
            models: KVec::new(),
            next: 0,
        }
    }

    /// The bus with `cards` fresh cores, each allocated on its own.
    fn alloc(cards: usize) -> Result<KBox<Self>> {
        let mut bus = KBox::new(Self::new(cards), GFP_KERNEL)?;
        bus.models.reserve(cards, GFP_KERNEL)?;
        for _ in 0..cards {
            bus.models.push(Model::with_rx_words(), GFP_KERNEL)?;
        }
        Ok(bus)
    }

    fn cards(&self) -> usize {
        self.models.len()
    }

    /// The bus condition the parameters name now. Any context.
    fn fault() -> (Fault, bool) {
        match param_word(&FAULT, &mut [0u8; FAULT_LEN]) {
            b"noack" => (Fault::NoAck, false),
            b"biterr" => {
                let capt = u8::try_from(FAULT_CAPT.get())
                    .unwrap_or(err_capt(err_type::BIT, err_pos::DATA));
                (Fault::BusError { capt }, false)
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

    /// One attempt by the first core (in turn) with a ready TX buffer.
    fn round(&mut self, (fault, overrun): (Fault, bool)) -> Round {
        let copies = if overrun { OVERRUN_COPIES } else { 1 };
        let out = sim_bus::round(&mut self.models, &mut self.next, fault, copies);
        Round {
            moved: out.moved(),
            failed: out.failed(),
            held: out.held(),
        }
    }

    fn irq_line(&mut self, i: usize) -> bool {
        self.models.get(i).is_some_and(|m| m.irq_line())
    }

    /// Byte-wide access is not how this front-end reaches its models
    /// (the driver's 32-bit accesses go through
    /// [`SimCards::with_bus`]): never called; reads as an absent chip.
    fn read(&mut self, _i: usize, _r: u8) -> u8 {
        0xFF
    }

    /// Never called (see [`Bus::read`]).
    fn write(&mut self, _i: usize, _r: u8, _val: u8) {}

    /// Never called (see [`Bus::read`]): [`SimRegs::write32`] kicks the
    /// bus itself.
    fn is_tx_request(_r: u8, _val: u8) -> bool {
        false
    }

    fn card_irq(c: &Core<SimRegs>) -> bool {
        c.irq()
    }

    fn report(&self) {
        for (i, m) in self.models.iter().enumerate() {
            pr_info!(
                "rcan_ctucanfd_sim: core {}: {} frames sent, {} attempts failed\n",
                i,
                m.sent,
                m.tx_failed
            );
        }
    }
}

/// Register access of core `idx`: its model on the bus. Reads as a
/// device that went away (all ones) outside the module's lifetime.
pub(crate) struct SimRegs {
    idx: usize,
}

impl Regs for SimRegs {
    fn read32(&mut self, off: usize) -> u32 {
        SIM.with_bus(|b| b.models.get_mut(self.idx).map(|m| m.read32(off)))
            .flatten()
            .unwrap_or(u32::MAX)
    }

    /// A TX_COMMAND write marking a buffer ready kicks the bus (after the
    /// bus lock is released).
    fn write32(&mut self, off: usize, val: u32) {
        SIM.with_bus(|b| {
            if let Some(m) = b.models.get_mut(self.idx) {
                m.write32(off, val);
            }
        });
        if off == reg::TX_COMMAND && val & txcmd::TXCR != 0 {
            SIM.request_tx();
        }
    }
}

/// The module: its state is in [`SIM`], set up and torn down by the glue.
pub(crate) type SimModule = glue::module::Scoped<simcard::SimModule<Bus>>;

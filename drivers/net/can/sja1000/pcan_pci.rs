// SPDX-License-Identifier: GPL-2.0

//! rcan_pcan_pci: front-end of the SJA1000 driver for PEAK-System's
//! PCAN-PCI cards (PCI 001c:0001, thesis 5.3.8): up to four SJA1000s in
//! BAR 1, 0x400 bytes each with their registers 32-bit aligned, behind an
//! Infineon PSB4600 ("PITA") bridge in BAR 0 that must be brought out of
//! reset and that gates and latches each channel's interrupt. Every PITA
//! write is followed by a read (PCI write flush); the PITA's latch is
//! acknowledged after the chip's causes were handled ([`Regs::irq_done`]).
//!
//! Only register access and probing live here; the driver is
//! `sja1000.rs`, the PITA sequences are the host-tested
//! `crate::rcan_chips::sja1000_boards`. QEMU has no PCAN-PCI: the module loads and
//! binds nothing there.
//!
//! Contexts: probe/remove in process context (PCI core); register access
//! and the acknowledgement from every context the driver uses, serialised
//! per channel by the driver's chip lock. The PITA's ICR is shared by the
//! channels, but each channel only reads it and writes its own bit back
//! (write-1-to-clear), so channels need no common lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, sja1000};

use crate::rcan_chips::sja1000::{Config, Regs, CDR_CBP};
use crate::rcan_chips::sja1000_boards::{
    pita_ack, pita_init, pita_irq, SpacedRegs, PCAN_CHAN_SIZE, PCAN_MAX_CHANNELS,
};
use glue::pci::{self, IoMem};
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use sja1000::{add_channel, Channel};

/// Bytes of PITA registers mapped from BAR 0.
const PITA_BYTES: usize = 0x20;
/// Output control: TX0 push-pull, TX1 unused (PEAK's value).
const PCAN_OCR: u8 = 0x1A;
/// Clock divider: comparator bypass, clock out off.
const PCAN_CDR: u8 = CDR_CBP | 0x08;
/// Crystal of the SJA1000s on the card.
const XTAL_HZ: u32 = 16_000_000;

/// PEAK's PCI configuration register cleared at probe.
const PCAN_CFG_44: i32 = 0x44;

/// Channels on the card, from its PCI subsystem id (PEAK's numbering).
fn channels_of(subsystem: u16) -> usize {
    match subsystem {
        12.. => 4,
        10..=11 => 3,
        4..=9 => 2,
        _ => 1,
    }
}

fn config() -> Config {
    sja1000::module_config(PCAN_OCR, PCAN_CDR)
}

/// One channel's register access: its SJA1000 (32-bit spacing) and the
/// PITA, for the interrupt acknowledgement.
struct PcanRegs {
    sja: SpacedRegs<IoMem>,
    pita: IoMem,
    ch: usize,
}

impl Regs for PcanRegs {
    fn read(&mut self, reg: u8) -> u8 {
        self.sja.read(reg)
    }
    fn write(&mut self, reg: u8, val: u8) {
        self.sja.write(reg, val);
    }
    fn irq_done(&mut self) -> bool {
        pita_ack(&mut self.pita, self.ch)
    }
}

/// A bound card.
struct Card {
    channels: KVec<Channel<PcanRegs>>,
    pita: IoMem,
    _enabled: pci::Enabled,
}

impl Card {
    fn irq_enable(&mut self, on: bool) {
        for ch in 0..self.channels.len() {
            pita_irq(&mut self.pita, ch, on);
        }
    }
}

struct PcanPci;

impl pci::Driver for PcanPci {
    type Data = Card;

    fn probe(dev: &pci::Device, scope: &ModuleScope) -> Result<KBox<Card>> {
        let enabled = dev.enable()?;
        // PEAK's configuration register 0x44 cleared (as PEAK's and
        // mainline's drivers do) before the PITA is touched.
        dev.write_config_word(PCAN_CFG_44, 0)?;
        let channels = channels_of(dev.subsystem_id());
        let mut pita = dev.iomap(0, PITA_BYTES)?;
        pita_init(&mut pita);
        // Interrupts of all channels off until their devices exist.
        for ch in 0..PCAN_MAX_CHANNELS {
            pita_irq(&mut pita, ch, false);
        }
        let mut card = Card {
            channels: KVec::new(),
            pita,
            _enabled: enabled,
        };
        for ch in 0..channels {
            let regs = PcanRegs {
                sja: SpacedRegs {
                    io: dev.iomap(1, channels * PCAN_CHAN_SIZE)?,
                    base: ch * PCAN_CHAN_SIZE,
                    shift: 2,
                },
                pita: dev.iomap(0, PITA_BYTES)?,
                ch,
            };
            // A channel the subsystem id promises but that does not
            // answer ends the card.
            let Some(c) = add_channel(
                scope,
                regs,
                config(),
                dev.irq(),
                XTAL_HZ,
                format_args!("channel {ch} of a PEAK PCAN-PCI"),
            )?
            else {
                break;
            };
            card.channels.push(c, GFP_KERNEL)?;
        }
        if card.channels.is_empty() {
            pr_err!("no SJA1000 found behind the PITA\n");
            return Err(ENODEV);
        }
        card.irq_enable(true);
        Ok(KBox::new(card, GFP_KERNEL)?)
    }

    fn remove(mut card: KBox<Card>) {
        card.irq_enable(false);
        drop(card);
    }
}

/// The PCI ids the driver matches (`DRIVER.register` gets [`IDS`], a
/// copy). The module root exports another copy under the symbol name
/// modpost reads (`MODULE_DEVICE_TABLE(pci, ...)`), which makes these the
/// module's `pci:v...` aliases: one list for matching and autoloading.
pub(crate) const PCI_IDS: [glue::pci::DeviceId; 2] = [pci::id(0x001c, 0x0001), pci::ID_END];

static IDS: [glue::pci::DeviceId; 2] = PCI_IDS;

static DRIVER: pci::Registration<PcanPci> = pci::Registration::new();

pub(crate) struct PcanPciModule;

impl ScopedModule for PcanPciModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        DRIVER.register(c_str!("rcan_pcan_pci"), &IDS, scope)?;
        Ok(PcanPciModule)
    }
}

impl Drop for PcanPciModule {
    fn drop(&mut self) {
        DRIVER.unregister();
    }
}

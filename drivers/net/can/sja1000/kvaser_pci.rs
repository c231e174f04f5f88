// SPDX-License-Identifier: GPL-2.0

//! rcan_kvaser_pci: front-end of the SJA1000 driver for the Kvaser
//! PCIcan cards (PCI 10e8:8406), as QEMU's `kvaser_pci` device emulates
//! them: up to four SJA1000s in an I/O BAR (32 bytes each), behind an AMCC
//! S5920 whose INTCSR register gates the card's interrupt. Only register
//! access and probing live here; the driver is `sja1000.rs`.
//!
//! BARs (mainline kvaser_pci.c documents the card the same way): 0 = S5920
//! configuration registers, 1 = the SJA1000 channels, 2 = Xilinx logic.
//!
//! Contexts: probe/remove in process context (PCI core); register access
//! from every context the driver uses, serialised by the driver's chip
//! lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, sja1000};

use crate::rcan_chips::sja1000::{Config, CDR_CBP};
use glue::pci::{self, IoMem};
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use sja1000::{add_channel, Channel, IoRegs};

const MAX_CHANNELS: usize = 4;
/// Bytes of I/O space per channel.
const CHANNEL_BYTES: usize = 0x20;
/// S5920 interrupt control/status register and its add-on interrupt
/// enable bit.
const S5920_INTCSR: usize = 0x38;
const INTCSR_ADDON_INTENABLE: u32 = 0x2000;
/// Output control: both TX pins push-pull (mainline KVASER_PCI_OCR).
const KVASER_OCR: u8 = 0xDA;
/// Clock divider: comparator bypass, clock out at full rate.
const KVASER_CDR: u8 = CDR_CBP | 0x07;

/// Bit timing from the module parameters (`btr0`, `btr1`; defaults from
/// the thesis' Kconfig: 0x01/0x14, 500 kbit/s).
fn config() -> Config {
    sja1000::module_config(KVASER_OCR, KVASER_CDR)
}

/// Crystal of the SJA1000s on the card.
const XTAL_HZ: u32 = 16_000_000;

/// A bound card.
struct Card {
    channels: KVec<Channel<IoRegs>>,
    conf: IoMem,
    _enabled: pci::Enabled,
}

impl Card {
    fn irq_enable(&self, on: bool) {
        let v = self.conf.read32(S5920_INTCSR);
        let v = if on {
            v | INTCSR_ADDON_INTENABLE
        } else {
            v & !INTCSR_ADDON_INTENABLE
        };
        self.conf.write32(S5920_INTCSR, v);
    }
}

struct KvaserPci;

impl pci::Driver for KvaserPci {
    type Data = Card;

    fn probe(dev: &pci::Device, scope: &ModuleScope) -> Result<KBox<Card>> {
        let enabled = dev.enable()?;
        let conf = dev.iomap(0, 0x80)?;
        let mut card = Card {
            channels: KVec::new(),
            conf,
            _enabled: enabled,
        };
        card.irq_enable(false);
        for ch in 0..MAX_CHANNELS {
            let regs = IoRegs {
                io: dev.iomap(1, MAX_CHANNELS * CHANNEL_BYTES)?,
                base: ch * CHANNEL_BYTES,
                shift: 0,
            };
            // The channels are contiguous: the first empty slot ends the
            // card.
            let Some(c) = add_channel(
                scope,
                regs,
                config(),
                dev.irq(),
                XTAL_HZ,
                format_args!("channel {ch} of a Kvaser PCIcan"),
            )?
            else {
                break;
            };
            card.channels.push(c, GFP_KERNEL)?;
        }
        if card.channels.is_empty() {
            pr_err!("kvaser_pci: no SJA1000 found\n");
            return Err(ENODEV);
        }
        card.irq_enable(true);
        Ok(KBox::new(card, GFP_KERNEL)?)
    }

    fn remove(card: KBox<Card>) {
        card.irq_enable(false);
        drop(card);
    }
}

/// The PCI ids the driver matches (`DRIVER.register` gets [`IDS`], a
/// copy). The module root exports another copy under the symbol name
/// modpost reads (`MODULE_DEVICE_TABLE(pci, ...)`), which makes these the
/// module's `pci:v...` aliases: one list for matching and autoloading.
pub(crate) const PCI_IDS: [glue::pci::DeviceId; 2] = [pci::id(0x10e8, 0x8406), pci::ID_END];

static IDS: [glue::pci::DeviceId; 2] = PCI_IDS;

static DRIVER: pci::Registration<KvaserPci> = pci::Registration::new();

pub(crate) struct KvaserPciModule;

impl ScopedModule for KvaserPciModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        DRIVER.register(c_str!("rcan_kvaser_pci"), &IDS, scope)?;
        Ok(KvaserPciModule)
    }
}

impl Drop for KvaserPciModule {
    fn drop(&mut self) {
        DRIVER.unregister();
    }
}

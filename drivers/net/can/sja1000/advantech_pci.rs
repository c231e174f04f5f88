// SPDX-License-Identifier: GPL-2.0

//! rcan_advantech_pci: front-end of the SJA1000 driver for the two-channel
//! Advantech PCI cards QEMU emulates: PCM-3680I (PCI 13fe:c002, registers
//! at byte spacing) and MIOe-3680 (PCI 13fe:c302, registers at 32-bit
//! spacing). Each channel's SJA1000 is in its own I/O BAR (0 and 1); both
//! share the card's interrupt line, which needs no gating. Not a thesis
//! front-end: it exists so that the driver runs on a second card type in
//! the VM.
//!
//! Contexts: probe/remove in process context (PCI core); register access
//! from every context the driver uses, serialised by the chip lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, sja1000};

use crate::rcan_chips::sja1000::{Config, CDR_CBP};
use glue::pci;
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use sja1000::{add_channel, Channel, IoRegs};

const CHANNELS: usize = 2;
/// Output control: TX0 push-pull, normal mode (what these boards use).
const ADVANTECH_OCR: u8 = 0xDA;
/// Clock divider: comparator bypass, clock out off.
const ADVANTECH_CDR: u8 = CDR_CBP | crate::rcan_chips::sja1000::CDR_CLK_OFF;

fn config() -> Config {
    sja1000::module_config(ADVANTECH_OCR, ADVANTECH_CDR)
}

/// Crystal of the SJA1000s on the card.
const XTAL_HZ: u32 = 16_000_000;

struct Card {
    channels: KVec<Channel<IoRegs>>,
    _enabled: pci::Enabled,
}

/// Register spacing (shift) by PCI device id.
fn shift_of(device: u16) -> u32 {
    if device == 0xc302 {
        2
    } else {
        0
    }
}

struct AdvantechPci;

impl pci::Driver for AdvantechPci {
    type Data = Card;

    fn probe(dev: &pci::Device, scope: &ModuleScope) -> Result<KBox<Card>> {
        let enabled = dev.enable()?;
        let shift = shift_of(dev.device_id());
        let mut card = Card {
            channels: KVec::new(),
            _enabled: enabled,
        };
        for ch in 0..CHANNELS {
            let regs = IoRegs {
                io: dev.iomap(ch as i32, 0x20 << shift)?,
                base: 0,
                shift,
            };
            let what = format_args!("channel {ch} of an Advantech {:04x} card", dev.device_id());
            if let Some(c) = add_channel(scope, regs, config(), dev.irq(), XTAL_HZ, what)? {
                card.channels.push(c, GFP_KERNEL)?;
            }
        }
        if card.channels.is_empty() {
            pr_err!("advantech_pci: no SJA1000 found\n");
            return Err(ENODEV);
        }
        Ok(KBox::new(card, GFP_KERNEL)?)
    }

    fn remove(card: KBox<Card>) {
        drop(card);
    }
}

/// The PCI ids the driver matches (`DRIVER.register` gets [`IDS`], a
/// copy). The module root exports another copy under the symbol name
/// modpost reads (`MODULE_DEVICE_TABLE(pci, ...)`), which makes these the
/// module's `pci:v...` aliases: one list for matching and autoloading.
pub(crate) const PCI_IDS: [glue::pci::DeviceId; 3] = [
    pci::id(0x13fe, 0xc002),
    pci::id(0x13fe, 0xc302),
    pci::ID_END,
];

static IDS: [glue::pci::DeviceId; 3] = PCI_IDS;

static DRIVER: pci::Registration<AdvantechPci> = pci::Registration::new();

pub(crate) struct AdvantechPciModule;

impl ScopedModule for AdvantechPciModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        DRIVER.register(c_str!("rcan_advantech_pci"), &IDS, scope)?;
        Ok(AdvantechPciModule)
    }
}

impl Drop for AdvantechPciModule {
    fn drop(&mut self) {
        DRIVER.unregister();
    }
}

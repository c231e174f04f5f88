// SPDX-License-Identifier: GPL-2.0

//! `rcan_iomemkeep`: a test-only PCI driver for the VM test
//! `sja1000_kvaser_iomem_revoked` (`tests/vm/src/cases/sja1000.rs`,
//! issue 39, "A mapping past its binding" in architecture.rst). Safe
//! code, as every driver file, that does what no driver of the tree does
//! and nothing in the type system forbids: its `remove` moves the card's
//! register window ([`IoMem`]) and its [`pci::Enabled`] into a `static`,
//! where they outlive the binding, and the module's exit uses the window
//! after the device was unbound (and, in the test, bound to
//! `rcan_kvaser_pci` meanwhile).
//!
//! It matches no device by id: the test binds a Kvaser PCIcan to it with
//! sysfs `driver_override`. The window is the card's BAR 1, whose first
//! 32 bytes are the first SJA1000's registers.
//!
//! Logged for the test (`rcan_iomemkeep: ...` lines, the prefix
//! `pr_info!` adds): at probe, register
//! 0 (MOD in PeliCAN mode, CR in BasicCAN mode: bit 0 set after reset,
//! never 0xff); at exit, the same register read through the kept window,
//! then a write of 0x01 (reset mode) to it. With the binding revoked at
//! `remove`, the read gives 0xff and the write is dropped; without, the
//! read reaches the chip, and the write puts the chip that another driver
//! now runs into reset mode: its interface stops receiving.
#![forbid(unsafe_code)]

use crate::glue::lock::StaticIrqSpinLock;
use crate::glue::module::{ModuleScope, ScopedModule};
use crate::glue::pci::{self, IoMem};
use kernel::c_str;
use kernel::prelude::*;

/// The SJA1000 channels' BAR of a Kvaser PCIcan.
const BAR: i32 = 1;
/// Bytes of the first channel.
const WINDOW: usize = 0x20;
/// The register read and written: MOD (PeliCAN) or CR (BasicCAN).
const REG: usize = 0;
/// Reset mode (bit 0 of either register).
const RESET: u8 = 0x01;

/// What the probe takes and `remove` keeps.
struct Card {
    io: IoMem,
    _enabled: pci::Enabled,
}

/// The card kept past `remove`, until the module's exit.
static KEPT: StaticIrqSpinLock<Option<Card>> =
    StaticIrqSpinLock::new(None, c_str!("rcan_iomemkeep::KEPT"));

struct Keeper;

impl pci::Driver for Keeper {
    type Data = Card;

    fn probe(dev: &pci::Device, _scope: &ModuleScope) -> Result<KBox<Card>> {
        let enabled = dev.enable()?;
        let io = dev.iomap(BAR, WINDOW)?;
        pr_info!("probe: reg {} = {:#04x}\n", REG, io.read8(REG));
        Ok(KBox::new(
            Card {
                io,
                _enabled: enabled,
            },
            GFP_KERNEL,
        )?)
    }

    fn remove(card: KBox<Card>) {
        // The misuse: the window and the enable outlive the binding.
        let old = KEPT.lock().replace(KBox::into_inner(card));
        drop(old);
        pr_info!("remove: card kept\n");
    }
}

/// Ends the id table at once: binding is by `driver_override` only.
static IDS: [pci::DeviceId; 1] = [pci::ID_END];

static DRIVER: pci::Registration<Keeper> = pci::Registration::new();

pub(crate) struct IoMemKeep;

impl ScopedModule for IoMemKeep {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        DRIVER.register(c_str!("rcan_iomemkeep"), &IDS, scope)?;
        Ok(IoMemKeep)
    }
}

impl Drop for IoMemKeep {
    fn drop(&mut self) {
        DRIVER.unregister();
        // Taken out of the lock before use: dropping the enable sleeps.
        let kept = KEPT.lock().take();
        if let Some(card) = kept {
            let v = card.io.read8(REG);
            card.io.write8(REG, RESET);
            pr_info!("exit: reg {} = {:#04x} through the kept window\n", REG, v);
            drop(card);
        }
    }
}

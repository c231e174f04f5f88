// SPDX-License-Identifier: GPL-2.0

//! rcan_ctucanfd_pci: PCI front-end of the CTU CAN FD driver for the
//! CTU CAN FD PCIe card (PCI 1760:ff00) as QEMU's `ctucan_pci` device
//! emulates it: BAR 0 holds the card's identification word (0xC000_0000
//! plus the number of cores) and, at 0x4000, the Cyclone IV PCIe bridge
//! registers whose A2P interrupt enable gates the cores' interrupt on the
//! real card; BAR 1 holds the cores, 0x4000 bytes apart. All cores share
//! the card's interrupt line. Only register access and probing live
//! here; the driver is `ctucanfd.rs`.
//!
//! Module parameters `bitrate` and `dbitrate` (bit/s, default 0: none):
//! the bit timing every core starts with ([`Preset`]), computed
//! as `ip link set canX type can bitrate N dbitrate M` computes it; a
//! value no bit timing meets refuses the module load with `EINVAL` and a
//! kernel log line naming the parameter. With `rcan_dev rtnl_link=N`
//! (mainline's `can-dev` holding the link kind) they are the only way to
//! a bit timing; FD is then switched on with `ip link set canX mtu 72`.
//!
//! Contexts: probe/remove in process context (PCI core); register access
//! from every context the driver uses, serialised by each core's lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{ctucanfd, glue};

use crate::rcan_chips::ctucanfd::CORE_SPAN;
use crate::rcan_core::candev::{Preset, PresetError, Settings};
use ctucanfd::{add_core, Core, CtuCanFd, IoRegs};
use glue::params::Param;
use glue::pci::{self, IoMem};
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;

/// Offset of the card identification word in BAR 0.
const BAR0_CARD_ID: usize = 0x0000;
/// Offset of the PCIe bridge's A2P interrupt enable register in BAR 0.
const BAR0_CRA_A2P_IE: usize = 0x4000 + 0x50;
/// Bytes of BAR 0 the driver maps.
const BAR0_LEN: usize = 0x4000 + 0x54;
/// Most cores a card has (the identification word's 4-bit count).
const MAX_CORES: usize = 15;
/// The core clock on the card (mainline `ctucanfd_pci`: 100 MHz).
const CLOCK_HZ: u32 = 100_000_000;

/// Module parameter `bitrate` (number 0 in ctucanfd_pci_c.c, read-only).
const BITRATE: Param<u32> = Param::new(0);
/// Module parameter `dbitrate` (number 1, read-only).
const DBITRATE: Param<u32> = Param::new(1);

/// The settings every core starts with: the module parameters' rates
/// against the core's limits at the card's clock. Any context.
fn preset_settings() -> Result<Settings, PresetError> {
    let preset = Preset {
        bitrate: BITRATE.get(),
        dbitrate: DBITRATE.get(),
    };
    glue::can::dev::preset_settings::<CtuCanFd<IoRegs>>(&preset, CLOCK_HZ)
}

/// Number of cores from the identification word: its low four bits when
/// the top bits carry the card's 0xC000_0000 signature, else two (what
/// mainline assumes for older card firmware).
fn cores(id: u32) -> usize {
    if id & 0xF000_0000 == 0xC000_0000 {
        (id & 0xF) as usize
    } else {
        2
    }
}

/// A bound card.
struct Card {
    cores: KVec<Core<IoRegs>>,
    bar0: IoMem,
    _enabled: pci::Enabled,
}

impl Card {
    fn irq_enable(&self, on: bool) {
        self.bar0
            .write32(BAR0_CRA_A2P_IE, if on { 0xFFFF_FFFF } else { 0 });
    }
}

struct CtuCanFdPci;

impl pci::Driver for CtuCanFdPci {
    type Data = Card;

    fn probe(dev: &pci::Device, scope: &ModuleScope) -> Result<KBox<Card>> {
        let enabled = dev.enable()?;
        let bar0 = dev.iomap(0, BAR0_LEN)?;
        let n = cores(bar0.read32(BAR0_CARD_ID)).min(MAX_CORES);
        let mut card = Card {
            cores: KVec::new(),
            bar0,
            _enabled: enabled,
        };
        card.irq_enable(false);
        // Checked at module init; the parameters are read-only.
        let preset = preset_settings().unwrap_or_default();
        for i in 0..n {
            let regs = IoRegs {
                io: dev.iomap(1, n * CORE_SPAN)?,
                base: i * CORE_SPAN,
                cores: n,
            };
            let Some(c) = add_core(
                scope,
                regs,
                dev.irq(),
                CLOCK_HZ,
                preset,
                format_args!("core {i} of a CTU CAN FD PCI card"),
            )?
            else {
                pr_warn!("ctucanfd_pci: no core {} answers\n", i);
                continue;
            };
            card.cores.push(c, GFP_KERNEL)?;
        }
        if card.cores.is_empty() {
            pr_err!("ctucanfd_pci: no CTU CAN FD core found\n");
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

/// The PCI ids the driver matches; the module root exports a copy under
/// the symbol modpost reads, for the module's `pci:v...` aliases.
pub(crate) const PCI_IDS: [glue::pci::DeviceId; 2] = [pci::id(0x1760, 0xff00), pci::ID_END];

static IDS: [glue::pci::DeviceId; 2] = PCI_IDS;

static DRIVER: pci::Registration<CtuCanFdPci> = pci::Registration::new();

pub(crate) struct CtuCanFdPciModule;

impl ScopedModule for CtuCanFdPciModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        if let Err(e) = preset_settings() {
            pr_err!(
                "bitrate={} dbitrate={} refused for the card's {} Hz clock: {}\n",
                BITRATE.get(),
                DBITRATE.get(),
                CLOCK_HZ,
                e
            );
            return Err(EINVAL);
        }
        DRIVER.register(c_str!("rcan_ctucanfd_pci"), &IDS, scope)?;
        Ok(CtuCanFdPciModule)
    }
}

impl Drop for CtuCanFdPciModule {
    fn drop(&mut self) {
        DRIVER.unregister();
    }
}

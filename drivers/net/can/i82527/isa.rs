// SPDX-License-Identifier: GPL-2.0

//! rcan_i82527_isa: front-end of the 82527 driver for memory-mapped ISA
//! cards (thesis 5.3.11: STZP PC-I 03, RTD ECAN527/ECAN527D). ISA cannot
//! be probed for resources, so the user gives `iomem` (physical address
//! of the 82527's 256-byte window) and `irq`. At load the memory region
//! is requested and mapped and the chip probed; the driver (`i82527.rs`)
//! registers the interrupt at open and puts the chip in INIT (off the
//! bus) and frees the interrupt at stop. Only register access lives here.
//!
//! Without a card (as in QEMU, which emulates none) the window reads
//! 0xFF or behaves as memory, the probe fails, and loading fails with
//! ENODEV.
//!
//! Register access runs in every context the driver uses (process,
//! softirq, hardirq), serialised by the driver's chip lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, i82527};

use crate::rcan_chips::i82527::{Config, Regs};
use glue::isa::{IoWindow, Space};
use glue::params::Param;
use i82527::{add_channel, Channel};
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;

/// Crystal of the cards the thesis used (16 MHz).
const XTAL_HZ: u32 = 16_000_000;

/// Bytes of the 82527's register window.
const WINDOW_BYTES: usize = 0x100;

// Parameter numbers shared with isa_c.c.
/// `iomem=`: physical address of the window (required).
const IOMEM: Param<usize> = Param::new(0);
/// `irq=`: the card's interrupt line (required).
const IRQ: Param<i32> = Param::new(1);
const BT0: Param<u8> = Param::new(2);
const BT1: Param<u8> = Param::new(3);
const CPU_IF: Param<u8> = Param::new(4);
const CLKOUT: Param<u8> = Param::new(5);
const BUS_CFG: Param<u8> = Param::new(6);

/// Register access through the claimed and mapped window (readb/writeb;
/// the default readn/writen are the thesis' memcpy_fromio/memcpy_toio
/// byte by byte, which the 82527's byte-wide bus needs anyway). Every
/// register number (< 256) lies inside the window.
struct IsaRegs(IoWindow);

impl Regs for IsaRegs {
    fn read(&mut self, reg: u8) -> u8 {
        self.0.read8(reg.into())
    }
    fn write(&mut self, reg: u8, val: u8) {
        self.0.write8(reg.into(), val)
    }
}

pub(crate) struct IsaModule {
    _channel: Channel<IsaRegs>,
}

impl ScopedModule for IsaModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let (iomem, irq) = (IOMEM.get(), IRQ.get());
        if iomem == 0 || irq <= 0 || irq > 0xFFFF {
            pr_err!("rcan_i82527_isa: iomem= and irq= are required\n");
            return Err(ENODEV);
        }
        let cfg = Config {
            bt0: BT0.get(),
            bt1: BT1.get(),
            cpu_if: CPU_IF.get(),
            clkout: CLKOUT.get(),
            bus_cfg: BUS_CFG.get(),
        };
        let regs = IsaRegs(IoWindow::request(
            Space::Mem,
            iomem,
            WINDOW_BYTES,
            c_str!("rcan_i82527_isa"),
        )?);
        match add_channel(
            scope,
            regs,
            cfg,
            irq as u32,
            XTAL_HZ,
            format_args!("ISA at {iomem:#x}"),
        )? {
            Some(c) => Ok(IsaModule { _channel: c }),
            None => {
                pr_info!("rcan_i82527_isa: no 82527 at {:#x}\n", iomem);
                Err(ENODEV)
            }
        }
    }
}

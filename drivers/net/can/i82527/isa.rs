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

use kernel::prelude::*;

#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "i82527.rs"]
mod i82527;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

use i82527::{add_channel, Channel};
use rcan_core::i82527::{Config, Regs};

module! {
    type: IsaModule,
    name: "rcan_i82527_isa",
    author: "rcan developers",
    description: "Intel 82527 front-end for memory-mapped ISA cards",
    license: "GPL",
}

/// Crystal of the cards the thesis used (16 MHz).
const XTAL_HZ: u32 = 16_000_000;

extern "C" {
    fn rcan_i82527_isa_param(which: i32) -> u64;
    fn rcan_i82527_isa_map(phys: u64, err: *mut i32) -> *mut kernel::ffi::c_void;
    fn rcan_i82527_isa_unmap(phys: u64, p: *mut kernel::ffi::c_void);
    fn rcan_i82527_isa_readb(p: *mut kernel::ffi::c_void, reg: u8) -> u8;
    fn rcan_i82527_isa_writeb(p: *mut kernel::ffi::c_void, reg: u8, val: u8);
}

fn param(which: i32) -> u64 {
    // SAFETY: reads a module parameter (READ_ONCE); any index is valid.
    unsafe { rcan_i82527_isa_param(which) }
}

/// The requested and mapped register window.
///
/// # Invariants
///
/// `p` maps 256 bytes at `phys`, requested by `rcan_i82527_isa_map`,
/// released in Drop.
struct Window {
    phys: u64,
    p: *mut kernel::ffi::c_void,
}

// SAFETY: the mapping may be used and released from any thread.
unsafe impl Send for Window {}

impl Window {
    fn map(phys: u64) -> Result<Window> {
        let mut err = 0i32;
        // SAFETY: `err` is writable; the helper requests and maps or fails.
        let p = unsafe { rcan_i82527_isa_map(phys, &mut err) };
        if p.is_null() {
            return Err(Error::from_errno(err));
        }
        // INVARIANT: mapped above.
        Ok(Window { phys, p })
    }
}

impl Drop for Window {
    fn drop(&mut self) {
        // SAFETY: mapped and requested by rcan_i82527_isa_map (invariant).
        unsafe { rcan_i82527_isa_unmap(self.phys, self.p) };
    }
}

/// Register access through the window (readb/writeb; the default
/// readn/writen are the thesis' memcpy_fromio/memcpy_toio byte by byte,
/// which the 82527's byte-wide bus needs anyway).
struct IsaRegs(Window);

impl Regs for IsaRegs {
    fn read(&mut self, reg: u8) -> u8 {
        // SAFETY: `reg` < 256 lies in the mapped window (Window invariant).
        unsafe { rcan_i82527_isa_readb(self.0.p, reg) }
    }
    fn write(&mut self, reg: u8, val: u8) {
        // SAFETY: as in read.
        unsafe { rcan_i82527_isa_writeb(self.0.p, reg, val) }
    }
}

struct IsaModule {
    _channel: Channel<IsaRegs>,
}

impl kernel::Module for IsaModule {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        let (iomem, irq) = (param(0), param(1));
        if iomem == 0 || irq <= 0 || irq > 0xFFFF {
            pr_err!("rcan_i82527_isa: iomem= and irq= are required\n");
            return Err(ENODEV);
        }
        let cfg = Config {
            bt0: param(2) as u8,
            bt1: param(3) as u8,
            cpu_if: param(4) as u8,
            clkout: param(5) as u8,
            bus_cfg: param(6) as u8,
        };
        let regs = IsaRegs(Window::map(iomem)?);
        match add_channel(
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

// SPDX-License-Identifier: GPL-2.0

//! rcan_sja1000_isa: front-end of the SJA1000 driver for memory-mapped ISA
//! cards (thesis 5.3.7). Each card's SJA1000 occupies 32 bytes of the ISA
//! memory hole at the address given with `iomem=` (up to eight cards,
//! comma-separated); its interrupt line is `irq=` or, when that is 0 or
//! missing, found by the interrupt autoprobe: with every free line enabled
//! (`probe_irq_on`) the chip is put to sleep and woken, which raises its
//! wake-up interrupt, and `probe_irq_off` names the line that fired.
//!
//! Only register access and probing live here; the driver is
//! `sja1000.rs`, the autoprobe sequence is the host-tested
//! `crate::rcan_chips::sja1000_boards`.
//!
//! Contexts: everything here runs in module init/exit (process context);
//! register access from the driver is serialised by its chip lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, sja1000};

use crate::rcan_chips::sja1000::{cmd, reg, Chip, Config, Regs, CDR_CBP};
use crate::rcan_chips::sja1000_boards::{autoprobe_ack, autoprobe_arm, autoprobe_fire, SpacedRegs};
use glue::isa::{self, IoWindow, Space};
use glue::params::{Param, ParamArray};
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use sja1000::{add_probed, Channel};

/// Bytes of memory per SJA1000 (registers 0..31, byte spacing).
const WINDOW_BYTES: usize = 32;
/// Output control: both TX pins push-pull.
const ISA_OCR: u8 = 0xDA;
/// Clock divider: comparator bypass, clock out off.
const ISA_CDR: u8 = CDR_CBP | 0x08;
/// Crystal of the usual ISA boards.
const XTAL_HZ: u32 = 16_000_000;
/// Attempts to put the chip to sleep for the autoprobe (it refuses while
/// the bus is busy).
const AUTOPROBE_TRIES: usize = 3;

// Parameter numbers shared with sja1000_isa_c.c (0 and 1 are the core's
// BTR0/BTR1).
/// Cards given with `iomem=` (at most 8).
const BOARDS: Param<u32> = Param::new(2);
/// `iomem=`: each card's address.
const IOMEM: ParamArray<usize> = ParamArray::new(3);
/// `irq=`: each card's line; 0 or missing: autoprobe.
const IRQ: ParamArray<i32> = ParamArray::new(4);

type IsaRegs = SpacedRegs<IoWindow>;

fn config() -> Config {
    sja1000::module_config(ISA_OCR, ISA_CDR)
}

/// Finds the interrupt line of the probed chip: the thesis' sleep-to-wake
/// autoprobe. Process context; takes about 100 ms per attempt.
fn autoprobe(chip: &mut Chip<IsaRegs>, addr: usize) -> Result<u32> {
    for _ in 0..AUTOPROBE_TRIES {
        let mask = isa::probe_irq_on();
        if autoprobe_arm(chip).is_err() {
            // Busy bus: end this probe round and try again.
            let _ = isa::probe_irq_off(mask);
            continue;
        }
        autoprobe_fire(chip);
        // The wake-up interrupt is raised as the oscillator restarts.
        isa::udelay(100);
        let line = isa::probe_irq_off(mask);
        let woke = autoprobe_ack(chip).unwrap_or(false);
        match line {
            Some(Ok(n)) if woke => return Ok(n),
            Some(Err(())) => {
                pr_warn!("{addr:#x}: several lines fired in the autoprobe, retrying\n")
            }
            _ => {}
        }
    }
    pr_err!("{addr:#x}: no interrupt line found by the autoprobe; give irq=\n");
    Err(ENODEV)
}

/// Claims, maps and probes the card at `addr`; registers its device.
fn add_board(scope: &ModuleScope, addr: usize, line: i32) -> Result<Channel<IsaRegs>> {
    let win = match IoWindow::request(Space::Mem, addr, WINDOW_BYTES, c_str!("rcan_sja1000_isa")) {
        Ok(w) => w,
        Err(e) => {
            pr_err!("iomem {addr:#x}: memory region busy or not mappable\n");
            return Err(e);
        }
    };
    let mut chip = Chip::new(
        SpacedRegs {
            io: win,
            base: 0,
            shift: 0,
        },
        config(),
    );
    if chip.probe().is_err() {
        // Dropping the chip unmaps and releases the window.
        pr_err!("iomem {addr:#x}: no SJA1000 answers (reset mode not entered)\n");
        return Err(ENODEV);
    }
    // The reset-mode check alone cannot tell the chip from plain memory
    // (RAM in the ISA hole echoes every write). The command register is
    // write-only (PeliCAN mode reads 0x00, BasicCAN 0xFF); "clear data
    // overrun" is harmless in reset mode. Memory reads it back.
    chip.regs.write(reg::CMR, cmd::CDO);
    if chip.regs.read(reg::CMR) == cmd::CDO {
        pr_err!("iomem {addr:#x}: memory, not an SJA1000 (command register reads back)\n");
        return Err(ENODEV);
    }
    let irq = if line > 0 {
        line as u32
    } else {
        autoprobe(&mut chip, addr)?
    };
    add_probed(
        scope,
        chip,
        irq,
        XTAL_HZ,
        format_args!("ISA card at iomem {addr:#x}"),
    )
}

pub(crate) struct IsaModule {
    _boards: KVec<Channel<IsaRegs>>,
}

impl ScopedModule for IsaModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let n = BOARDS.get();
        if n == 0 {
            pr_err!("no card given (iomem=ADDR[,ADDR...])\n");
            return Err(EINVAL);
        }
        let mut boards = KVec::new();
        for i in 0..n {
            // Any failure unwinds the boards added so far (dropped with
            // `boards`): all cards given must be there.
            boards.push(add_board(scope, IOMEM.get(i), IRQ.get(i))?, GFP_KERNEL)?;
        }
        Ok(IsaModule { _boards: boards })
    }
}

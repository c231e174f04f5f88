// SPDX-License-Identifier: GPL-2.0

//! rcan_tscan1: front-end of the SJA1000 driver for Technologic Systems'
//! TS-CAN1 PC/104 boards (thesis 5.3.9), in the I/O port space. A board's
//! PLD sits at one of four addresses (jumpers JP1/JP2: 0x150, 0x158,
//! 0x160, 0x168); each is claimed, probed and identified by the PLD's
//! two fixed registers; the interrupt line comes from jumpers JP4/JP5;
//! the SJA1000 is then mapped ("page" selection in the PLD's mode
//! register) to the first of its eight possible I/O addresses that no
//! other driver owns. Up to four boards.
//!
//! Only register access and probing live here; the driver is
//! `sja1000.rs`, identification and mapping are the host-tested
//! `crate::rcan_chips::sja1000_boards`.
//!
//! Contexts: module init/exit (process context); register access from
//! the driver is serialised by its chip lock.
#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::{glue, sja1000};

use crate::rcan_chips::sja1000::{Config, CDR_CBP};
use crate::rcan_chips::sja1000_boards::{
    tscan1_identify, tscan1_map, tscan1_unmap, Io, SpacedRegs, Tscan1, Tscan1Error,
    TSCAN1_MAX_BOARDS, TSCAN1_PLD, TSCAN1_PLD_SIZE, TSCAN1_SJA1000_ADDRESSES, TSCAN1_SJA1000_SIZE,
};
use glue::isa::{IoWindow, Space};
use glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use sja1000::{add_channel, Channel};

/// Output control: both TX pins push-pull.
const TSCAN1_OCR: u8 = 0xDA;
/// Clock divider: comparator bypass, clock out off.
const TSCAN1_CDR: u8 = CDR_CBP | 0x08;
/// Crystal of the board's SJA1000.
const XTAL_HZ: u32 = 16_000_000;

fn config() -> Config {
    sja1000::module_config(TSCAN1_OCR, TSCAN1_CDR)
}

/// The claimed PLD window seen as the port space the board logic
/// addresses by port number; ports outside the window read 0xFF and are
/// not written.
struct PldPorts<'a>(&'a IoWindow);

impl Io for PldPorts<'_> {
    fn inb(&mut self, port: usize) -> u8 {
        self.0.read8(port.wrapping_sub(self.0.start()))
    }
    fn outb(&mut self, port: usize, val: u8) {
        self.0.write8(port.wrapping_sub(self.0.start()), val);
    }
}

/// A bound board.
struct Board {
    /// Taken (unregistered) first in Drop, before the PLD unmaps the chip.
    chan: Option<Channel<SpacedRegs<IoWindow>>>,
    info: Tscan1,
    pld: IoWindow,
}

impl Drop for Board {
    fn drop(&mut self) {
        drop(self.chan.take());
        tscan1_unmap(&mut PldPorts(&self.pld), &self.info);
    }
}

/// Probes board `n`; `Ok(None)` if there is none.
fn probe_board(scope: &ModuleScope, n: usize) -> Result<Option<Board>> {
    let port = TSCAN1_PLD + n * TSCAN1_PLD_SIZE;
    let Ok(pld) = IoWindow::request(Space::Port, port, TSCAN1_PLD_SIZE, c_str!("rcan_tscan1"))
    else {
        pr_info!("PLD ports {port:#x} owned by another driver, skipped\n");
        return Ok(None);
    };
    let info = match tscan1_identify(&mut PldPorts(&pld), n) {
        Ok(i) => i,
        Err(Tscan1Error::NoBoard) => return Ok(None),
        Err(Tscan1Error::NoIrq) => {
            pr_err!("board at {port:#x}: jumpers JP4/JP5 select no interrupt line\n");
            return Ok(None);
        }
    };
    for (page, &addr) in TSCAN1_SJA1000_ADDRESSES.iter().enumerate() {
        let Ok(win) = IoWindow::request(
            Space::Port,
            addr,
            TSCAN1_SJA1000_SIZE,
            c_str!("rcan_tscan1"),
        ) else {
            continue;
        };
        let mapped = tscan1_map(&mut PldPorts(&pld), &info, page);
        let regs = SpacedRegs {
            io: win,
            base: 0,
            shift: 0,
        };
        let what = format_args!("TS-CAN1 at PLD {port:#x}, SJA1000 at {mapped:#x}");
        return match add_channel(scope, regs, config(), info.irq, XTAL_HZ, what) {
            Ok(Some(c)) => Ok(Some(Board {
                chan: Some(c),
                info,
                pld,
            })),
            Ok(None) => {
                tscan1_unmap(&mut PldPorts(&pld), &info);
                pr_err!("board at {port:#x}: no SJA1000 answers at {mapped:#x}\n");
                Ok(None)
            }
            Err(e) => {
                tscan1_unmap(&mut PldPorts(&pld), &info);
                Err(e)
            }
        };
    }
    pr_err!("board at {port:#x}: all SJA1000 addresses owned by other drivers\n");
    Ok(None)
}

pub(crate) struct Tscan1Module {
    _boards: KVec<Board>,
}

impl ScopedModule for Tscan1Module {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let mut boards = KVec::new();
        for n in 0..TSCAN1_MAX_BOARDS {
            if let Some(b) = probe_board(scope, n)? {
                boards.push(b, GFP_KERNEL)?;
            }
        }
        if boards.is_empty() {
            pr_err!(
                "no TS-CAN1 board (no PLD identification at {:#x}..{:#x})\n",
                TSCAN1_PLD,
                TSCAN1_PLD + (TSCAN1_MAX_BOARDS - 1) * TSCAN1_PLD_SIZE
            );
            return Err(ENODEV);
        }
        Ok(Tscan1Module { _boards: boards })
    }
}

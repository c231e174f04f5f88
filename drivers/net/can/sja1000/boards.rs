// SPDX-License-Identifier: GPL-2.0

//! Board logic of the thesis' SJA1000 front-ends that QEMU cannot emulate
//! (5.3.7-5.3.9): register access and probing of the memory-mapped ISA
//! card (`sja1000_isa`, with the interrupt autoprobe), PEAK's PCAN-PCI
//! (`pcan_pci`, SJA1000s behind the Infineon PSB4600 "PITA" bridge) and
//! Technologic Systems' TS-CAN1 (`tscan1`, PC/104, a PLD that maps the
//! SJA1000 into the I/O space). Pure: a front-end module supplies an
//! [`Io`] for its window (memory or ports) and runs these sequences; the
//! host tests run them against register-level models.

use super::sja1000::{irq, mode, reg, Chip, Regs, Sja1000Error};

/// Byte and 16-bit access to one I/O window (a port range, a mapped ISA
/// memory window or a PCI BAR). Offsets are relative to the window.
pub trait Io {
    /// Reads a byte.
    fn inb(&mut self, off: usize) -> u8;
    /// Writes a byte.
    fn outb(&mut self, off: usize, val: u8);
    /// Reads a little-endian 16-bit word.
    fn inw(&mut self, off: usize) -> u16 {
        u16::from(self.inb(off)) | u16::from(self.inb(off + 1)) << 8
    }
    /// Writes a little-endian 16-bit word.
    fn outw(&mut self, off: usize, val: u16) {
        self.outb(off, val as u8);
        self.outb(off + 1, (val >> 8) as u8);
    }
}

/// SJA1000 registers in a window at `base`, `1 << shift` bytes apart
/// (ISA and TS-CAN1: 0; PCAN-PCI: 2, 32-bit aligned).
pub struct SpacedRegs<I: Io> {
    /// The window.
    pub io: I,
    /// Offset of register 0.
    pub base: usize,
    /// Register spacing as a shift.
    pub shift: u32,
}

impl<I: Io> Regs for SpacedRegs<I> {
    fn read(&mut self, r: u8) -> u8 {
        self.io.inb(self.base + (usize::from(r) << self.shift))
    }
    fn write(&mut self, r: u8, v: u8) {
        self.io.outb(self.base + (usize::from(r) << self.shift), v);
    }
}

// ---- ISA: interrupt autoprobe -------------------------------------------

/// First half of the thesis' IRQ autoprobe for an ISA card whose `irq`
/// parameter was not given (5.3.7): the driver calls `probe_irq_on()`,
/// then this, which arms the wake-up interrupt and puts the chip to sleep
/// (operating mode, sleep bit set, only WUI enabled).
pub fn autoprobe_arm<R: Regs>(chip: &mut Chip<R>) -> Result<(), Sja1000Error> {
    chip.enter_reset()?;
    let _ = chip.regs.read(reg::IR);
    chip.regs.write(reg::IER, irq::WUI);
    // Leave reset mode first: sleep can only be entered in operating mode.
    chip.regs.write(reg::MOD, 0);
    chip.regs.write(reg::MOD, mode::SM);
    if chip.regs.read(reg::MOD) & mode::SM == 0 {
        // The chip refuses to sleep only while the bus is busy or an
        // interrupt is pending; the caller retries or gives up.
        chip.enter_reset()?;
        return Err(Sja1000Error::Busy);
    }
    Ok(())
}

/// Second half: wakes the chip by clearing the sleep bit, which makes it
/// raise the wake-up interrupt on its line; the driver then calls
/// `probe_irq_off()` to learn which line fired.
pub fn autoprobe_fire<R: Regs>(chip: &mut Chip<R>) {
    chip.regs.write(reg::MOD, 0);
}

/// Last step: whether the chip did raise WUI (read clears it); back to
/// reset mode with interrupts off either way.
pub fn autoprobe_ack<R: Regs>(chip: &mut Chip<R>) -> Result<bool, Sja1000Error> {
    let ir = chip.regs.read(reg::IR);
    chip.enter_reset()?;
    Ok(ir & irq::WUI != 0)
}

// ---- PEAK PCAN-PCI (PITA bridge) ----------------------------------------

/// PITA registers in the configuration BAR.
pub mod pita {
    /// Interrupt control/status (16 bit): a channel's status bit, written
    /// back to clear it.
    pub const ICR: usize = 0x00;
    /// Interrupt enable (16 bit, high half of ICR).
    pub const ICR_ENABLE: usize = 0x02;
    /// GPIO interface control.
    pub const GPIOICR: usize = 0x18;
    /// Miscellaneous register.
    pub const MISC: usize = 0x1C;
}

/// Bytes of the channel BAR per channel.
pub const PCAN_CHAN_SIZE: usize = 0x400;
/// Most channels on one PCAN-PCI card.
pub const PCAN_MAX_CHANNELS: usize = 4;
/// ICR bit of each channel (PITA interrupt inputs as wired on the cards).
pub const PCAN_ICR_MASKS: [u16; PCAN_MAX_CHANNELS] = [0x02, 0x01, 0x40, 0x80];

/// Brings the PITA out of reset and out of parallel-port mux mode. Each
/// write is followed by a read of the same register: the PCI bridge may
/// post writes, and the chips behind it must see them in order (the
/// thesis' "PCI write flush").
pub fn pita_init<I: Io>(cfg: &mut I) {
    cfg.outw(pita::GPIOICR + 2, 0x0005);
    let _ = cfg.inw(pita::GPIOICR + 2);
    cfg.outb(pita::GPIOICR, 0x00);
    let _ = cfg.inb(pita::GPIOICR);
    cfg.outb(pita::MISC + 3, 0x04);
    let _ = cfg.inb(pita::MISC + 3);
}

/// Enables or disables channel `ch`'s interrupt in the PITA.
pub fn pita_irq<I: Io>(cfg: &mut I, ch: usize, on: bool) {
    let m = PCAN_ICR_MASKS[ch % PCAN_MAX_CHANNELS];
    let v = cfg.inw(pita::ICR_ENABLE);
    cfg.outw(pita::ICR_ENABLE, if on { v | m } else { v & !m });
    let _ = cfg.inw(pita::ICR_ENABLE);
}

/// Acknowledges channel `ch`'s interrupt in the PITA after the chip's
/// causes were handled; returns whether it was pending.
pub fn pita_ack<I: Io>(cfg: &mut I, ch: usize) -> bool {
    let m = PCAN_ICR_MASKS[ch % PCAN_MAX_CHANNELS];
    if cfg.inw(pita::ICR) & m == 0 {
        return false;
    }
    cfg.outw(pita::ICR, m);
    let _ = cfg.inw(pita::ICR);
    true
}

// ---- TS-CAN1 (PC/104) ----------------------------------------------------

/// I/O port of the first board's PLD; board `n` (jumpers JP1/JP2) is at
/// `TSCAN1_PLD + 8 n`.
pub const TSCAN1_PLD: usize = 0x150;
/// Bytes of PLD registers per board.
pub const TSCAN1_PLD_SIZE: usize = 8;
/// Most boards in one system.
pub const TSCAN1_MAX_BOARDS: usize = 4;
/// Bytes of SJA1000 I/O space.
pub const TSCAN1_SJA1000_SIZE: usize = 32;
/// The I/O addresses the PLD can map the SJA1000 to (MODE bits 2..0).
pub const TSCAN1_SJA1000_ADDRESSES: [usize; 8] =
    [0x100, 0x120, 0x180, 0x1a0, 0x200, 0x240, 0x280, 0x320];

/// PLD registers.
pub mod pld {
    /// Fixed identification byte 1 (0xF6).
    pub const ID1: usize = 0;
    /// Fixed identification byte 2 (0xB9).
    pub const ID2: usize = 1;
    /// LED.
    pub const LED: usize = 3;
    /// Mode: enable bit and the SJA1000 address ("page") selection.
    pub const MODE: usize = 5;
    /// Jumpers JP4/JP5 select the interrupt line.
    pub const JUMPERS: usize = 6;
    /// Values of ID1 and ID2.
    pub const ID_VALUES: (u8, u8) = (0xF6, 0xB9);
    /// MODE: map the SJA1000 into the I/O space.
    pub const MODE_ENABLE: u8 = 0x40;
    /// JUMPERS: JP4 and JP5.
    pub const JP4: u8 = 0x10;
    /// See [`JP4`].
    pub const JP5: u8 = 0x20;
}

/// A TS-CAN1 board found by [`tscan1_identify`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Tscan1 {
    /// I/O port of its PLD.
    pub pld: usize,
    /// Interrupt line set by JP4/JP5.
    pub irq: u32,
}

/// Why a TS-CAN1 probe failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Tscan1Error {
    /// No PLD with the identification bytes at that address.
    NoBoard,
    /// JP4/JP5 select no interrupt line.
    NoIrq,
}

/// Looks for board `n` (0..3) in the port space `ports` (offsets are port
/// numbers): checks the PLD's identification bytes and reads the
/// interrupt line from the jumpers.
pub fn tscan1_identify<I: Io>(ports: &mut I, n: usize) -> Result<Tscan1, Tscan1Error> {
    let pld = TSCAN1_PLD + n * TSCAN1_PLD_SIZE;
    if (ports.inb(pld + pld::ID1), ports.inb(pld + pld::ID2)) != pld::ID_VALUES {
        return Err(Tscan1Error::NoBoard);
    }
    let irq = match ports.inb(pld + pld::JUMPERS) & (pld::JP4 | pld::JP5) {
        pld::JP4 => 6,
        pld::JP5 => 7,
        j if j == pld::JP4 | pld::JP5 => 5,
        _ => return Err(Tscan1Error::NoIrq),
    };
    Ok(Tscan1 { pld, irq })
}

/// Maps the board's SJA1000 to `TSCAN1_SJA1000_ADDRESSES[page]` and
/// returns that port.
pub fn tscan1_map<I: Io>(ports: &mut I, b: &Tscan1, page: usize) -> usize {
    let page = page % TSCAN1_SJA1000_ADDRESSES.len();
    ports.outb(b.pld + pld::MODE, pld::MODE_ENABLE | page as u8);
    TSCAN1_SJA1000_ADDRESSES[page]
}

/// Unmaps the board's SJA1000 (module exit, or a failed probe) and turns
/// the LED off.
pub fn tscan1_unmap<I: Io>(ports: &mut I, b: &Tscan1) {
    ports.outb(b.pld + pld::MODE, 0);
    ports.outb(b.pld + pld::LED, 0);
}

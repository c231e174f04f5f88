// SPDX-License-Identifier: GPL-2.0
//! A register-level model of the SJA1000 in PeliCAN mode, for host tests
//! of the driver core (`rcan_core::sja1000::Chip`). It follows the
//! datasheet for what the driver touches: reset/operating mode, the
//! acceptance registers that exist only in reset mode, the TX buffer and
//! TR/SRR/AT commands, the 64-byte receive FIFO with RRB and data overrun,
//! the interrupt register (read clears all but RI, which follows the
//! FIFO), the status register, error counters, bus-off entering reset.

use rcan_core::frame::CanFrame;
use rcan_core::sja1000::{cmd, decode, encode, irq, mode, reg, status, HwFilter, Regs};
use std::collections::VecDeque;

#[derive(Default)]
pub struct Sja1000Model {
    pub mode: u8,
    pub ier: u8,
    pub ir: u8,
    pub dos: bool,
    pub tcs: bool,
    pub btr: [u8; 2],
    pub ocr: u8,
    pub cdr: u8,
    pub acr: [u8; 4],
    pub amr: [u8; 4],
    pub tx: [u8; 13],
    pub rxerr: u8,
    pub txerr: u8,
    pub busoff: bool,
    /// Frames in the receive FIFO (images), oldest first.
    pub fifo: VecDeque<[u8; 13]>,
    /// Frames the chip put on the bus.
    pub sent: Vec<CanFrame>,
    /// Every register access, for counting.
    pub accesses: usize,
    /// No chip at this address: reads give 0xFF, writes vanish.
    pub absent: bool,
}

/// Bytes a frame takes in the 64-byte FIFO.
fn fifo_bytes(img: &[u8; 13]) -> usize {
    let dlc = usize::from(img[0] & 0x0F).min(8);
    let rtr = img[0] & 0x40 != 0;
    (if img[0] & 0x80 != 0 { 5 } else { 3 }) + if rtr { 0 } else { dlc }
}

impl Sja1000Model {
    pub fn new() -> Self {
        // Power-on: reset mode.
        Sja1000Model {
            mode: mode::RM,
            ..Default::default()
        }
    }

    fn in_reset(&self) -> bool {
        self.mode & mode::RM != 0
    }

    pub fn filter(&self) -> HwFilter {
        HwFilter {
            single: self.mode & mode::AFM != 0,
            acr: self.acr,
            amr: self.amr,
        }
    }

    fn raise(&mut self, bit: u8) {
        if self.ier & bit != 0 {
            self.ir |= bit;
        }
    }

    /// A frame from the bus. Returns whether it reached the FIFO.
    pub fn deliver(&mut self, f: &CanFrame) -> bool {
        if self.in_reset() || !self.filter().accepts(f) {
            return false;
        }
        let img = encode(f).unwrap().0;
        let used: usize = self.fifo.iter().map(fifo_bytes).sum();
        if used + fifo_bytes(&img) > 64 {
            self.dos = true;
            self.raise(irq::DOI);
            return false;
        }
        self.fifo.push_back(img);
        self.raise(irq::RI);
        true
    }

    /// Sets the error counters as bus errors would, raising EI/EPI like
    /// the chip; a transmit counter above 255 is bus-off (reset mode).
    pub fn set_errors(&mut self, rxerr: u8, txerr: u8, busoff: bool) {
        let was_es = self.rxerr >= 96 || self.txerr >= 96 || self.busoff;
        let was_ep = self.rxerr > 127 || self.txerr > 127;
        self.rxerr = rxerr;
        self.txerr = txerr;
        self.busoff = busoff;
        if busoff {
            self.mode |= mode::RM;
        }
        let es = rxerr >= 96 || txerr >= 96 || busoff;
        let ep = rxerr > 127 || txerr > 127;
        if es != was_es || busoff {
            self.raise(irq::EI);
        }
        if ep != was_ep {
            self.raise(irq::EPI);
        }
    }

    fn sr(&self) -> u8 {
        let mut sr = status::TBS;
        if !self.fifo.is_empty() {
            sr |= status::RBS;
        }
        if self.dos {
            sr |= status::DOS;
        }
        if self.tcs {
            sr |= status::TCS;
        }
        if self.rxerr >= 96 || self.txerr >= 96 || self.busoff {
            sr |= status::ES;
        }
        if self.busoff {
            sr |= status::BS;
        }
        sr
    }

    /// Whether the interrupt line is asserted.
    pub fn irq_pending(&self) -> bool {
        self.ir & self.ier != 0
    }
}

impl Regs for Sja1000Model {
    fn read(&mut self, r: u8) -> u8 {
        self.accesses += 1;
        if self.absent {
            return 0xFF;
        }
        match r {
            reg::MOD => self.mode,
            reg::SR => self.sr(),
            reg::IR => {
                let v = self.ir;
                // Reading clears everything but RI, which stays while the
                // FIFO holds frames.
                self.ir = if self.fifo.is_empty() { 0 } else { v & irq::RI };
                v
            }
            reg::IER => self.ier,
            reg::BTR0 => self.btr[0],
            reg::BTR1 => self.btr[1],
            reg::OCR => self.ocr,
            reg::RXERR => self.rxerr,
            reg::TXERR => self.txerr,
            reg::CDR => self.cdr,
            0x10..=0x13 if self.in_reset() => self.acr[usize::from(r - 0x10)],
            0x14..=0x17 if self.in_reset() => self.amr[usize::from(r - 0x14)],
            0x10..=0x1C => self
                .fifo
                .front()
                .map_or(0, |img| img[usize::from(r - 0x10)]),
            _ => 0,
        }
    }

    fn write(&mut self, r: u8, v: u8) {
        self.accesses += 1;
        if self.absent {
            return;
        }
        match r {
            reg::MOD => {
                let sleeping = !self.in_reset() && self.mode & mode::SM != 0;
                self.mode = v;
                // Sleep is refused in reset mode and while an interrupt
                // is pending; leaving it raises the wake-up interrupt.
                if v & mode::SM != 0 && (v & mode::RM != 0 || self.irq_pending()) {
                    self.mode &= !mode::SM;
                }
                if sleeping && self.mode & mode::SM == 0 {
                    self.raise(irq::WUI);
                }
            }
            reg::CMR => {
                if v & cmd::RRB != 0 {
                    self.fifo.pop_front();
                    if self.fifo.is_empty() {
                        self.ir &= !irq::RI;
                    }
                }
                if v & cmd::CDO != 0 {
                    self.dos = false;
                }
                if v & (cmd::TR | cmd::SRR) != 0 && !self.in_reset() {
                    let f = decode(&self.tx);
                    self.sent.push(f);
                    self.tcs = true;
                    self.raise(irq::TI);
                    if v & cmd::SRR != 0 {
                        self.deliver(&f);
                    }
                }
            }
            reg::IER => self.ier = v,
            reg::BTR0 if self.in_reset() => self.btr[0] = v,
            reg::BTR1 if self.in_reset() => self.btr[1] = v,
            reg::OCR if self.in_reset() => self.ocr = v,
            reg::RXERR if self.in_reset() => self.rxerr = v,
            reg::TXERR if self.in_reset() => {
                self.txerr = v;
                self.busoff = false;
            }
            reg::CDR if self.in_reset() => self.cdr = v,
            0x10..=0x13 if self.in_reset() => self.acr[usize::from(r - 0x10)] = v,
            0x14..=0x17 if self.in_reset() => self.amr[usize::from(r - 0x14)] = v,
            0x10..=0x1C if !self.in_reset() => self.tx[usize::from(r - 0x10)] = v,
            _ => {}
        }
    }
}

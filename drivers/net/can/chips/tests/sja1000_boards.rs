// SPDX-License-Identifier: GPL-2.0
//! The thesis' SJA1000 front-ends that QEMU cannot emulate (5.3.7-5.3.9),
//! through their access functions and probe logic against models: the
//! ISA card's interrupt autoprobe (sleep-to-wake interrupt), PEAK
//! PCAN-PCI's 32-bit register spacing and PITA interrupt control, and
//! TS-CAN1's PLD identification, jumper decoding and I/O mapping, each
//! finishing with a frame sent and received through the driver core.

mod common;

use common::sja1000_model::{Fault, Sja1000Model, TxAttempt};
use rcan_chips::sja1000::{Chip, Config, Event, HwFilter, Regs, CDR_CBP};
use rcan_chips::sja1000_boards::*;
use rcan_core::frame::CanFrame;

const CFG: Config = Config {
    btr0: 0x01,
    btr1: 0x14,
    ocr: 0xDA,
    cdr: CDR_CBP,
};

fn frame(id: u32, data: &[u8]) -> CanFrame {
    let mut f = CanFrame {
        can_id: id,
        len: data.len() as u8,
        ..CanFrame::default()
    };
    f.data[..data.len()].copy_from_slice(data);
    f
}

/// A chip reachable through a window: byte registers at `1 << shift`
/// spacing from `base`.
struct ChipWindow<'a> {
    chip: &'a mut Sja1000Model,
    base: usize,
    shift: u32,
    /// Bytes the window decodes (accesses outside float: 0xFF).
    len: usize,
}

impl Io for ChipWindow<'_> {
    fn inb(&mut self, off: usize) -> u8 {
        let o = off.wrapping_sub(self.base);
        if off < self.base || o >= self.len || o & ((1 << self.shift) - 1) != 0 {
            return 0xFF;
        }
        self.chip.read((o >> self.shift) as u8)
    }
    fn outb(&mut self, off: usize, val: u8) {
        let o = off.wrapping_sub(self.base);
        if off >= self.base && o < self.len && o & ((1 << self.shift) - 1) == 0 {
            self.chip.write((o >> self.shift) as u8, val);
        }
    }
}

/// Runs a chip through a frame each way and returns the events of the
/// receive.
fn exchange<R: Regs>(chip: &mut Chip<R>, model: impl Fn(&mut Chip<R>) -> &mut Sja1000Model) {
    chip.init(&HwFilter::OPEN).unwrap();
    chip.start(&HwFilter::OPEN).unwrap();
    chip.xmit(&frame(0x123, &[1, 2])).unwrap();
    assert_eq!(
        model(chip).transmit(Fault::None, true),
        TxAttempt::Sent(frame(0x123, &[1, 2]))
    );
    assert_eq!(model(chip).last_sent, Some(frame(0x123, &[1, 2])));
    let mut ev = Vec::new();
    chip.irq(20, |e| ev.push(e));
    assert_eq!(ev, vec![Event::TxDone]);
    assert!(model(chip).deliver(&frame(0x456, &[3])));
    ev.clear();
    chip.irq(20, |e| ev.push(e));
    assert_eq!(ev, vec![Event::Rx(frame(0x456, &[3]))]);
}

#[test]
fn isa_irq_autoprobe_raises_wakeup() {
    let mut m = Sja1000Model::new();
    let mut chip = Chip::new(
        SpacedRegs {
            io: ChipWindow {
                chip: &mut m,
                base: 0,
                shift: 0,
                len: 32,
            },
            base: 0,
            shift: 0,
        },
        CFG,
    );
    chip.probe().unwrap();
    autoprobe_arm(&mut chip).unwrap();
    // Asleep, and no interrupt yet: probe_irq_off would see nothing.
    assert!(!chip.regs.io.chip.irq_pending());
    autoprobe_fire(&mut chip);
    assert!(chip.regs.io.chip.irq_pending(), "leaving sleep raises WUI");
    assert_eq!(autoprobe_ack(&mut chip), Ok(true));
    assert!(!chip.regs.io.chip.irq_pending());
    assert_eq!(chip.regs.io.chip.ier, 0, "interrupts off after the probe");
    exchange(&mut chip, |c| &mut *c.regs.io.chip);
}

#[test]
fn isa_autoprobe_without_chip_finds_nothing() {
    let mut m = Sja1000Model::new();
    m.absent = true;
    let mut chip = Chip::new(
        SpacedRegs {
            io: ChipWindow {
                chip: &mut m,
                base: 0,
                shift: 0,
                len: 32,
            },
            base: 0,
            shift: 0,
        },
        CFG,
    );
    assert!(chip.probe().is_err());
}

/// PITA model: ICR status (set when a channel's chip interrupts),
/// enable bits, and the init registers.
#[derive(Default)]
struct Pita {
    icr: u16,
    enable: u16,
    gpioicr: [u8; 4],
    misc: [u8; 4],
    reads: usize,
}

impl Io for Pita {
    fn inb(&mut self, off: usize) -> u8 {
        self.reads += 1;
        match off {
            0 => self.icr as u8,
            1 => (self.icr >> 8) as u8,
            2 => self.enable as u8,
            3 => (self.enable >> 8) as u8,
            0x18..=0x1B => self.gpioicr[off - 0x18],
            0x1C..=0x1F => self.misc[off - 0x1C],
            _ => 0xFF,
        }
    }
    fn outb(&mut self, off: usize, v: u8) {
        match off {
            // Write-1-to-clear status.
            0 => self.icr &= !u16::from(v),
            1 => self.icr &= !(u16::from(v) << 8),
            2 => self.enable = (self.enable & 0xFF00) | u16::from(v),
            3 => self.enable = (self.enable & 0x00FF) | (u16::from(v) << 8),
            0x18..=0x1B => self.gpioicr[off - 0x18] = v,
            0x1C..=0x1F => self.misc[off - 0x1C] = v,
            _ => {}
        }
    }
}

#[test]
fn pcan_pci_registers_and_pita() {
    let mut cfg = Pita::default();
    pita_init(&mut cfg);
    assert_eq!(
        (cfg.gpioicr[2], cfg.gpioicr[0], cfg.misc[3]),
        (0x05, 0x00, 0x04)
    );
    assert!(cfg.reads >= 3, "every PITA write is flushed by a read");
    // Channel 1 of a two-channel card: registers 32-bit aligned at 0x400.
    let mut m = Sja1000Model::new();
    let mut chip = Chip::new(
        SpacedRegs {
            io: ChipWindow {
                chip: &mut m,
                base: PCAN_CHAN_SIZE,
                shift: 2,
                len: 0x80,
            },
            base: PCAN_CHAN_SIZE,
            shift: 2,
        },
        CFG,
    );
    chip.probe().unwrap();
    pita_irq(&mut cfg, 1, true);
    assert_eq!(cfg.enable, PCAN_ICR_MASKS[1]);
    exchange(&mut chip, |c| &mut *c.regs.io.chip);
    // The chip's interrupt shows in the PITA status; the handler acks it
    // after the chip's causes, and only its own bit.
    cfg.icr = PCAN_ICR_MASKS[1] | PCAN_ICR_MASKS[0];
    assert!(pita_ack(&mut cfg, 1));
    assert_eq!(cfg.icr, PCAN_ICR_MASKS[0]);
    assert!(!pita_ack(&mut cfg, 1));
    pita_irq(&mut cfg, 1, false);
    assert_eq!(cfg.enable, 0);
}

/// ISA port space with TS-CAN1 boards: PLDs and their SJA1000s, each
/// SJA1000 decoded at the address its PLD's MODE selects.
struct Ports {
    plds: Vec<Option<[u8; 8]>>,
    chips: Vec<Sja1000Model>,
}

impl Ports {
    fn mapped(&self, port: usize) -> Option<(usize, usize)> {
        self.plds.iter().enumerate().find_map(|(i, p)| {
            let p = p.as_ref()?;
            let mode = p[pld::MODE];
            if mode & pld::MODE_ENABLE == 0 {
                return None;
            }
            let base = TSCAN1_SJA1000_ADDRESSES[usize::from(mode & 7)];
            (port >= base && port < base + TSCAN1_SJA1000_SIZE).then_some((i, port - base))
        })
    }
}

impl Io for Ports {
    fn inb(&mut self, port: usize) -> u8 {
        if let Some(n) = port.checked_sub(TSCAN1_PLD).map(|o| o / TSCAN1_PLD_SIZE) {
            if let Some(Some(p)) = self.plds.get(n) {
                return p[(port - TSCAN1_PLD) % TSCAN1_PLD_SIZE];
            }
        }
        match self.mapped(port) {
            Some((i, r)) => self.chips[i].read(r as u8),
            None => 0xFF,
        }
    }
    fn outb(&mut self, port: usize, v: u8) {
        if let Some(n) = port.checked_sub(TSCAN1_PLD).map(|o| o / TSCAN1_PLD_SIZE) {
            if let Some(Some(p)) = self.plds.get_mut(n) {
                let r = (port - TSCAN1_PLD) % TSCAN1_PLD_SIZE;
                if r >= 3 {
                    p[r] = v;
                }
                return;
            }
        }
        if let Some((i, r)) = self.mapped(port) {
            self.chips[i].write(r as u8, v);
        }
    }
}

fn pld(jumpers: u8) -> Option<[u8; 8]> {
    Some([0xF6, 0xB9, 0x01, 0xFF, 0, 0, jumpers, 0])
}

#[test]
fn tscan1_identify_jumpers_and_map() {
    let mut ports = Ports {
        plds: vec![pld(pld::JP4), None, pld(pld::JP4 | pld::JP5), pld(0)],
        chips: (0..4).map(|_| Sja1000Model::new()).collect(),
    };
    assert_eq!(
        tscan1_identify(&mut ports, 0),
        Ok(Tscan1 { pld: 0x150, irq: 6 })
    );
    assert_eq!(tscan1_identify(&mut ports, 1), Err(Tscan1Error::NoBoard));
    assert_eq!(
        tscan1_identify(&mut ports, 2),
        Ok(Tscan1 { pld: 0x160, irq: 5 })
    );
    assert_eq!(tscan1_identify(&mut ports, 3), Err(Tscan1Error::NoIrq));

    // Board 2's SJA1000 at the fourth address (0x1a0), driven through its
    // port window.
    let b = tscan1_identify(&mut ports, 2).unwrap();
    let base = tscan1_map(&mut ports, &b, 3);
    assert_eq!(base, 0x1a0);
    let mut chip = Chip::new(
        SpacedRegs {
            io: &mut ports,
            base,
            shift: 0,
        },
        CFG,
    );
    chip.probe().unwrap();
    exchange(&mut chip, |c| &mut c.regs.io.chips[2]);
    assert_eq!(ports.chips[0].sent, 0, "board 0's chip untouched");
    tscan1_unmap(&mut ports, &b);
    assert_eq!(ports.plds[2].unwrap()[pld::MODE], 0);
    // Unmapped: nothing answers at the address any more.
    let mut gone = Chip::new(
        SpacedRegs {
            io: &mut ports,
            base,
            shift: 0,
        },
        CFG,
    );
    assert!(gone.probe().is_err());
}

impl Io for &mut Ports {
    fn inb(&mut self, port: usize) -> u8 {
        (**self).inb(port)
    }
    fn outb(&mut self, port: usize, v: u8) {
        (**self).outb(port, v)
    }
}

/// The PCAN-PCI front-end's register access as rcan_pcan_pci builds it:
/// the channel's spaced registers plus the PITA, acknowledged through
/// the post-interrupt hook [`Regs::irq_done`].
struct PcanRegs<'a> {
    sja: SpacedRegs<ChipWindow<'a>>,
    pita: &'a mut Pita,
    ch: usize,
}

impl Regs for PcanRegs<'_> {
    fn read(&mut self, r: u8) -> u8 {
        self.sja.read(r)
    }
    fn write(&mut self, r: u8, v: u8) {
        self.sja.write(r, v);
    }
    fn irq_done(&mut self) -> bool {
        pita_ack(self.pita, self.ch)
    }
}

#[test]
fn pcan_pci_irq_done_hook_acks_after_the_chip() {
    let mut m = Sja1000Model::new();
    let mut pita = Pita::default();
    let mut chip = Chip::new(
        PcanRegs {
            sja: SpacedRegs {
                io: ChipWindow {
                    chip: &mut m,
                    base: 0,
                    shift: 2,
                    len: 0x80,
                },
                base: 0,
                shift: 2,
            },
            pita: &mut pita,
            ch: 0,
        },
        CFG,
    );
    chip.probe().unwrap();
    chip.init(&HwFilter::OPEN).unwrap();
    chip.start(&HwFilter::OPEN).unwrap();
    // A frame arrives; the card latches channel 0's interrupt (and
    // channel 2's, which is not ours).
    assert!(chip.regs.sja.io.chip.deliver(&frame(0x42, &[9])));
    chip.regs.pita.icr = PCAN_ICR_MASKS[0] | PCAN_ICR_MASKS[2];
    let mut ev = Vec::new();
    assert!(chip.irq(20, |e| ev.push(e)));
    assert_eq!(ev, vec![Event::Rx(frame(0x42, &[9]))]);
    // What the driver does after the chip's causes: the hook clears only
    // this channel's latch and reports it pending once.
    assert!(chip.regs.irq_done());
    assert_eq!(chip.regs.pita.icr, PCAN_ICR_MASKS[2]);
    assert!(!chip.regs.irq_done());
}

#[test]
fn irq_done_defaults_to_nothing() {
    let mut m = Sja1000Model::new();
    let mut r = SpacedRegs {
        io: ChipWindow {
            chip: &mut m,
            base: 0,
            shift: 0,
            len: 0x20,
        },
        base: 0,
        shift: 0,
    };
    assert!(!r.irq_done());
}

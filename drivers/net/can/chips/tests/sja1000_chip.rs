// SPDX-License-Identifier: GPL-2.0
//! The SJA1000 driver core (`rcan_chips::sja1000::Chip`) against the
//! register-level model in `common/sja1000_model.rs`: probing, the
//! initialisation sequence, transmit and its completion, receive FIFO
//! draining, data overrun, error state changes and bus-off, and the
//! hardware filter keeping unwanted frames out of the FIFO.

mod common;

use common::sja1000_model::{Fault, Sja1000Model, TxAttempt};
use rcan_chips::sja1000::*;
use rcan_core::arb::{CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
use rcan_core::candev::err;
use rcan_core::frame::CanFrame;
use rcan_core::rxtable::{CanFilterKind, Filter};

const CFG: Config = Config {
    btr0: 0x01,
    btr1: 0x14,
    ocr: 0xDA,
    cdr: CDR_CBP,
};

fn frame(can_id: u32, data: &[u8]) -> CanFrame {
    let mut f = CanFrame {
        can_id,
        len: data.len() as u8,
        ..CanFrame::default()
    };
    f.data[..data.len()].copy_from_slice(data);
    f
}

fn running(filter: &HwFilter) -> Chip<Sja1000Model> {
    let mut c = Chip::new(Sja1000Model::new(), CFG);
    c.probe().unwrap();
    c.init(filter).unwrap();
    c.start(filter).unwrap();
    c
}

fn events(c: &mut Chip<Sja1000Model>) -> Vec<Event> {
    let mut v = Vec::new();
    c.irq(20, |e| v.push(e));
    v
}

#[test]
fn probe_finds_chip_or_nothing() {
    let mut c = Chip::new(Sja1000Model::new(), CFG);
    assert_eq!(c.probe(), Ok(()));
    let mut m = Sja1000Model::new();
    m.absent = true;
    assert_eq!(Chip::new(m, CFG).probe(), Err(Sja1000Error::NoChip));
}

#[test]
fn init_programs_timing_and_start_enters_operating_mode() {
    let mut c = Chip::new(Sja1000Model::new(), CFG);
    c.init(&HwFilter::OPEN).unwrap();
    assert_eq!(c.regs.btr, [0x01, 0x14]);
    assert_eq!(c.regs.ocr, 0xDA);
    assert_eq!(c.regs.cdr, CDR_PELICAN | CDR_CBP);
    assert_eq!(c.regs.amr, [0xFF; 4]);
    assert_ne!(c.regs.mode & mode::RM, 0, "init leaves reset mode on");
    c.start(&HwFilter::OPEN).unwrap();
    assert_eq!(c.regs.mode & mode::RM, 0);
    assert_eq!(c.regs.ier, irq::ENABLED);
    c.stop().unwrap();
    assert_ne!(c.regs.mode & mode::RM, 0);
    assert_eq!(c.regs.ier, 0);
}

#[test]
fn transmit_and_completion() {
    let mut c = running(&HwFilter::OPEN);
    let f = frame(0x1234_5678 | CAN_EFF_FLAG, &[1, 2, 3, 4, 5, 6, 7, 8]);
    c.xmit(&f).unwrap();
    assert!(c.regs.tx_pending);
    assert_eq!(c.regs.transmit(Fault::None, true), TxAttempt::Sent(f));
    assert_eq!((c.regs.sent, c.regs.last_sent), (1, Some(f)));
    assert_eq!(events(&mut c), vec![Event::TxDone]);
    assert!(!c.regs.irq_pending());
    assert_eq!(
        c.xmit(&frame(CAN_EFF_FLAG | 0x2000_0000 | 1, &[])),
        Err(Sja1000Error::BadFrame)
    );
}

#[test]
fn receive_drains_fifo_in_order() {
    let mut c = running(&HwFilter::OPEN);
    let frames = [
        frame(0x123, &[0xAA]),
        frame(0x7FF | CAN_RTR_FLAG, &[]),
        frame(CAN_EFF_FLAG | 0x1ABC_DEF0, &[1, 2, 3, 4, 5, 6, 7, 8]),
    ];
    for f in &frames {
        assert!(c.regs.deliver(f));
    }
    let got: Vec<Event> = events(&mut c);
    assert_eq!(
        got,
        frames.iter().map(|f| Event::Rx(*f)).collect::<Vec<_>>()
    );
    assert!(c.regs.fifo.is_empty());
    assert!(!c.regs.irq_pending());
}

#[test]
fn overrun_is_reported_and_cleared() {
    let mut c = running(&HwFilter::OPEN);
    let mut n = 0;
    while c.regs.deliver(&frame(CAN_EFF_FLAG | n, &[0; 8])) {
        n += 1;
    }
    // 64 bytes hold 4 extended 8-byte frames (13 bytes each).
    assert_eq!(n, 4);
    let ev = events(&mut c);
    assert!(ev.iter().any(|e| matches!(e, Event::Error(r)
        if r.frame.can_id & err::CRTL != 0 && r.frame.data[1] == err::CRTL_RX_OVERFLOW)));
    assert_eq!(ev.iter().filter(|e| matches!(e, Event::Rx(_))).count(), 4);
    assert!(!c.regs.dos, "CDO cleared the overrun");
    // The interface keeps working afterwards.
    assert!(c.regs.deliver(&frame(5, &[])));
    assert_eq!(events(&mut c), vec![Event::Rx(frame(5, &[]))]);
}

#[test]
fn error_states_and_bus_off() {
    let mut c = running(&HwFilter::OPEN);
    let states = |ev: Vec<Event>| -> Vec<(rcan_core::candev::CanState, bool)> {
        ev.iter()
            .filter_map(|e| match e {
                Event::Error(r) => Some((r.state, r.bus_off)),
                _ => None,
            })
            .collect()
    };
    use rcan_core::candev::CanState::*;
    c.regs.set_errors(0, 100, false);
    assert_eq!(states(events(&mut c)), vec![(ErrorWarning, false)]);
    c.regs.set_errors(0, 130, false);
    assert_eq!(states(events(&mut c)), vec![(ErrorPassive, false)]);
    c.regs.set_errors(0, 255, true);
    assert_eq!(states(events(&mut c)), vec![(BusOff, true)]);
    assert_eq!(c.state(), State::BusOff);
    assert_ne!(c.regs.mode & mode::RM, 0, "bus-off puts the chip in reset");
    // Recovery (mainline sja1000_start): restart clears the counters.
    c.start(&HwFilter::OPEN).unwrap();
    assert_eq!(c.state(), State::Active);
    assert_eq!(c.regs.mode & mode::RM, 0);
    assert_eq!((c.regs.rxerr, c.regs.txerr, c.regs.busoff), (0, 0, false));
}

#[test]
fn hardware_filter_keeps_unwanted_frames_out() {
    let exact = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
    let fs: Vec<Wanted> = [0x100u32, 0x200]
        .iter()
        .map(|&id| match Filter::from_can_filter(id, exact) {
            CanFilterKind::Frames(f) => Wanted::of(&f),
            CanFilterKind::Errors(_) => unreachable!(),
        })
        .collect();
    let hw = hw_filter(&fs, false);
    let mut c = running(&hw);
    assert!(c.regs.deliver(&frame(0x100, &[1])));
    assert!(c.regs.deliver(&frame(0x200, &[])));
    assert!(!c.regs.deliver(&frame(0x300, &[])));
    assert!(!c.regs.deliver(&frame(0x101, &[2])));
    // Reprogramming on a running chip.
    let mut drained = Vec::new();
    c.set_filter(&HwFilter::OPEN, true, |e| drained.push(e))
        .unwrap();
    assert_eq!(c.regs.mode & mode::RM, 0);
    assert!(c.regs.deliver(&frame(0x300, &[])));
    // The two frames accepted before the change were read out first.
    assert_eq!(
        drained,
        vec![Event::Rx(frame(0x100, &[1])), Event::Rx(frame(0x200, &[]))]
    );
}

#[test]
fn filter_change_loses_no_accepted_frame() {
    let mut c = running(&HwFilter::OPEN);
    for i in 0..4u32 {
        assert!(c.regs.deliver(&frame(0x10 + i, &[i as u8])));
    }
    let mut got = Vec::new();
    c.set_filter(&HwFilter::OPEN, true, |e| got.push(e))
        .unwrap();
    // Whatever the irq handler would read next is there too, in order.
    assert!(c.regs.deliver(&frame(0x20, &[])));
    got.extend(events(&mut c));
    let ids: Vec<u32> = got
        .iter()
        .filter_map(|e| match e {
            Event::Rx(f) => Some(f.can_id),
            _ => None,
        })
        .collect();
    assert_eq!(ids, vec![0x10, 0x11, 0x12, 0x13, 0x20]);
}

#[test]
fn start_discards_stale_frames() {
    let mut c = running(&HwFilter::OPEN);
    assert!(c.regs.deliver(&frame(0x111, &[1])));
    c.stop().unwrap();
    // A model of QEMU's behaviour: the FIFO survives reset mode.
    assert_eq!(c.regs.fifo.len(), 1);
    c.start(&HwFilter::OPEN).unwrap();
    assert!(c.regs.fifo.is_empty());
    assert!(events(&mut c).is_empty());
}

// SPDX-License-Identifier: GPL-2.0
//! Bus faults injected into the SJA1000 model (`rcan_chips::sja1000_model`)
//! and what the real driver core (`rcan_chips::sja1000::Chip`) makes of
//! them: the error frames, the error states, the CAN device and interface
//! statistics, bus-off and the restart, the control modes.
//!
//! The expected frames are worked out by hand from mainline's
//! `drivers/net/can/sja1000/sja1000.c` (`sja1000_err`, `sja1000_interrupt`,
//! `set_normal_mode`, `sja1000_start_xmit`), `dev.c`
//! (`can_change_state`) and `<linux/can/error.h>`: for each interrupt
//! round one frame, `CAN_ERR_FLAG` and DLC 8; `CAN_ERR_CNT` with TXERR in
//! data[6] and RXERR in data[7] unless bus-off; a bus error adds
//! `CAN_ERR_PROT | CAN_ERR_BUSERROR`, the ECC type in data[2]
//! (`CAN_ERR_PROT_TX` when transmitting) and the ECC segment in data[3].

mod common;

use common::sja1000_model::{ecc, Fault, Sja1000Model, TxAttempt};
use rcan_chips::sja1000::*;
use rcan_core::arb::{CAN_EFF_FLAG, CAN_ERR_FLAG};
use rcan_core::candev::{ctrlmode, err, CanState, CanStats, NetErrStats};
use rcan_core::frame::CanFrame;

const CFG: Config = Config {
    btr0: 0x00,
    btr1: 0x1C,
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

/// An error frame as `alloc_can_err_skb` + `sja1000_err` build it.
fn errf(class: u32, data: [u8; 8]) -> CanFrame {
    CanFrame {
        can_id: CAN_ERR_FLAG | class,
        len: 8,
        data,
        ..CanFrame::default()
    }
}

/// What the driver accumulates from the events, as the kernel driver does.
#[derive(Default, Debug)]
struct Seen {
    frames: Vec<CanFrame>,
    rx: Vec<CanFrame>,
    stats: CanStats,
    net: NetErrStats,
    tx_done: usize,
    tx_aborted: usize,
    bus_off: usize,
}

impl Seen {
    fn take(&mut self, e: Event) {
        match e {
            Event::Rx(f) => self.rx.push(f),
            Event::TxDone => self.tx_done += 1,
            Event::TxAborted => self.tx_aborted += 1,
            Event::Error(r) => {
                self.frames.push(r.frame);
                let s = &mut self.stats;
                s.bus_error += r.stats.bus_error;
                s.error_warning += r.stats.error_warning;
                s.error_passive += r.stats.error_passive;
                s.bus_off += r.stats.bus_off;
                s.arbitration_lost += r.stats.arbitration_lost;
                self.net.rx_errors += r.net.rx_errors;
                self.net.tx_errors += r.net.tx_errors;
                self.net.rx_over_errors += r.net.rx_over_errors;
                self.bus_off += usize::from(r.bus_off);
            }
        }
    }
}

fn running(modes: u32) -> Chip<Sja1000Model> {
    let mut c = Chip::new(Sja1000Model::new(), CFG);
    c.ctrlmode = modes;
    c.probe().unwrap();
    c.init(&HwFilter::OPEN).unwrap();
    c.start(&HwFilter::OPEN).unwrap();
    c
}

fn irq(c: &mut Chip<Sja1000Model>, seen: &mut Seen) {
    c.irq(20, |e| seen.take(e));
}

/// One transmission attempt with `fault`, then the interrupt handler.
fn attempt(c: &mut Chip<Sja1000Model>, seen: &mut Seen, fault: Fault) -> TxAttempt {
    let a = c.regs.transmit(fault, true);
    irq(c, seen);
    a
}

const PROT_BUS: u32 = err::PROT | err::BUSERROR;

#[test]
fn missing_ack_climbs_to_error_passive_and_stays() {
    let mut c = running(ctrlmode::BERR_REPORTING);
    assert_eq!(c.regs.ier, irq::ENABLED | irq::BEI);
    let mut s = Seen::default();
    c.xmit(&frame(0x123, &[1])).unwrap();
    for i in 1..=20u8 {
        assert_eq!(attempt(&mut c, &mut s, Fault::NoAck), TxAttempt::Failed);
        let txerr = (8 * u16::from(i)).min(128) as u8;
        assert_eq!(c.regs.txerr, txerr, "attempt {i}");
        let f = *s.frames.last().unwrap();
        // ECC: other error type, transmitting, ACK slot.
        let mut d = [0, 0, err::PROT_TX, err::PROT_LOC_ACK, 0, 0, txerr, 0];
        let mut class = PROT_BUS | err::CNT;
        if i == 12 {
            // TXERR reached the warning limit: EI in the same round.
            class |= err::CRTL;
            d[1] = err::CRTL_TX_WARNING;
        }
        if i == 16 {
            // Above 127: EPI.
            class |= err::CRTL;
            d[1] = err::CRTL_TX_PASSIVE;
        }
        assert_eq!(f, errf(class, d), "attempt {i}");
    }
    assert_eq!(s.frames.len(), 20);
    assert_eq!(c.can_state(), CanState::ErrorPassive);
    assert_eq!(
        s.stats,
        CanStats {
            bus_error: 20,
            error_warning: 1,
            error_passive: 1,
            ..CanStats::default()
        }
    );
    assert_eq!(s.net.tx_errors, 20);
    assert_eq!(s.tx_done, 0);
    // A node acknowledges again: the frame goes out, the counter drops.
    assert_eq!(
        attempt(&mut c, &mut s, Fault::None),
        TxAttempt::Sent(frame(0x123, &[1]))
    );
    assert_eq!(c.regs.txerr, 127);
    assert_eq!(s.tx_done, 1);
    // EPI again: back from passive. Mainline's sja1000_err turns an EPI
    // while passive into error warning (ES is still set at 127).
    assert_eq!(
        *s.frames.last().unwrap(),
        errf(
            err::CRTL | err::CNT,
            [0, err::CRTL_TX_WARNING, 0, 0, 0, 0, 127, 0]
        )
    );
    assert_eq!(c.can_state(), CanState::ErrorWarning);
}

#[test]
fn bit_errors_drive_the_chip_bus_off_and_restart_recovers() {
    let mut c = running(ctrlmode::BERR_REPORTING);
    let mut s = Seen::default();
    c.xmit(&frame(CAN_EFF_FLAG | 0x1234, &[1, 2, 3])).unwrap();
    let fault = Fault::BusError {
        ecc: ecc::TX_BIT_DATA,
    };
    for i in 1..=31u8 {
        assert_eq!(attempt(&mut c, &mut s, fault), TxAttempt::Failed);
        assert_eq!(c.regs.txerr, 8 * i, "attempt {i}");
    }
    assert_eq!(
        *s.frames.last().unwrap(),
        errf(
            PROT_BUS | err::CNT,
            [0, 0, err::PROT_BIT | err::PROT_TX, 0x0A, 0, 0, 248, 0]
        )
    );
    // The 32nd: past 255, bus-off. The frame has no counters (mainline
    // leaves them out in bus-off) and the bus error of the same round.
    assert_eq!(attempt(&mut c, &mut s, fault), TxAttempt::Failed);
    assert_eq!(
        *s.frames.last().unwrap(),
        errf(
            PROT_BUS | err::BUSOFF,
            [0, 0, err::PROT_BIT | err::PROT_TX, 0x0A, 0, 0, 0, 0]
        )
    );
    assert_eq!(s.bus_off, 1);
    assert_eq!(c.can_state(), CanState::BusOff);
    assert_eq!(c.state(), State::BusOff);
    assert_eq!(
        s.stats,
        CanStats {
            bus_error: 32,
            error_warning: 1,
            error_passive: 1,
            bus_off: 1,
            ..CanStats::default()
        }
    );
    // In reset mode, the transmission dropped, counters as the chip sets
    // them (TXERR 127).
    assert_ne!(c.regs.mode & mode::RM, 0);
    assert!(!c.regs.tx_pending);
    assert_eq!((c.regs.txerr, c.regs.rxerr), (127, 0));
    // Nothing moves while bus-off.
    assert_eq!(attempt(&mut c, &mut s, Fault::None), TxAttempt::Idle);
    // The restart (mainline sja1000_start): active, counters cleared, the
    // next frame goes out.
    c.start(&HwFilter::OPEN).unwrap();
    assert_eq!(c.can_state(), CanState::ErrorActive);
    assert_eq!((c.regs.txerr, c.regs.rxerr, c.regs.busoff), (0, 0, false));
    c.xmit(&frame(0x7, &[])).unwrap();
    assert_eq!(
        attempt(&mut c, &mut s, Fault::None),
        TxAttempt::Sent(frame(0x7, &[]))
    );
    assert_eq!(s.tx_done, 1);
}

#[test]
fn without_berr_reporting_only_state_changes_are_reported() {
    let mut c = running(0);
    assert_eq!(
        c.regs.ier,
        irq::ENABLED,
        "BEI off (mainline: IRQ_ALL & ~IRQ_BEI)"
    );
    let mut s = Seen::default();
    c.xmit(&frame(0x1, &[])).unwrap();
    let fault = Fault::BusError {
        ecc: ecc::TX_BIT_DATA,
    };
    for _ in 0..32 {
        attempt(&mut c, &mut s, fault);
    }
    assert_eq!(
        s.frames,
        vec![
            errf(
                err::CRTL | err::CNT,
                [0, err::CRTL_TX_WARNING, 0, 0, 0, 0, 96, 0]
            ),
            errf(
                err::CRTL | err::CNT,
                [0, err::CRTL_TX_PASSIVE, 0, 0, 0, 0, 128, 0]
            ),
            errf(err::BUSOFF, [0; 8]),
        ]
    );
    assert_eq!(s.stats.bus_error, 0, "bus errors not counted without BEI");
    assert_eq!(s.stats.bus_off, 1);
}

#[test]
fn arbitration_lost_is_reported_and_the_frame_retried() {
    let mut c = running(0);
    let mut s = Seen::default();
    c.xmit(&frame(0x300, &[5])).unwrap();
    let fault = Fault::ArbitrationLost { bit: 7 };
    assert_eq!(attempt(&mut c, &mut s, fault), TxAttempt::Failed);
    assert_eq!(
        s.frames,
        vec![errf(err::LOSTARB | err::CNT, [7, 0, 0, 0, 0, 0, 0, 0])]
    );
    assert_eq!(s.stats.arbitration_lost, 1);
    assert_eq!(c.regs.txerr, 0, "lost arbitration is no error");
    // The chip retries by itself and wins the next time.
    assert_eq!(
        attempt(&mut c, &mut s, fault),
        TxAttempt::Sent(frame(0x300, &[5]))
    );
    assert_eq!(s.tx_done, 1);
}

#[test]
fn data_overrun_is_reported_with_the_frames_that_fit() {
    let mut c = running(0);
    let mut s = Seen::default();
    let mut n = 0u32;
    while c.regs.deliver(&frame(CAN_EFF_FLAG | n, &[0; 8])) {
        n += 1;
    }
    irq(&mut c, &mut s);
    assert_eq!(s.rx.len(), 4);
    assert_eq!(
        s.frames,
        vec![errf(
            err::CRTL | err::CNT,
            [0, err::CRTL_RX_OVERFLOW, 0, 0, 0, 0, 0, 0]
        )]
    );
    assert_eq!((s.net.rx_over_errors, s.net.rx_errors), (1, 1));
    assert!(!c.regs.dos);
}

#[test]
fn receive_errors_reach_warning_and_passive_on_the_rx_side() {
    let mut c = running(ctrlmode::BERR_REPORTING);
    let mut s = Seen::default();
    for _ in 0..128 {
        c.regs.rx_error(ecc::STUFF | 0x02);
        irq(&mut c, &mut s);
    }
    let warn = s.frames[95];
    assert_eq!(
        warn,
        errf(
            err::CRTL | err::CNT | PROT_BUS,
            [0, err::CRTL_RX_WARNING, err::PROT_STUFF, 0x02, 0, 0, 0, 96]
        )
    );
    assert_eq!(
        s.frames[127],
        errf(
            err::CRTL | err::CNT | PROT_BUS,
            [0, err::CRTL_RX_PASSIVE, err::PROT_STUFF, 0x02, 0, 0, 0, 128]
        )
    );
    assert_eq!(s.net.rx_errors, 128);
    assert_eq!(c.can_state(), CanState::ErrorPassive);
    // A good frame brings RXERR back below 128 (to 119).
    assert!(c.regs.deliver(&frame(0x5, &[])));
    irq(&mut c, &mut s);
    assert_eq!(c.regs.rxerr, 119);
}

#[test]
fn one_shot_gives_up_after_one_failed_attempt() {
    let mut c = running(ctrlmode::ONE_SHOT);
    let mut s = Seen::default();
    c.xmit(&frame(0x10, &[1])).unwrap();
    assert_eq!(attempt(&mut c, &mut s, Fault::NoAck), TxAttempt::Failed);
    assert_eq!(s.tx_aborted, 1, "TI with TCS clear");
    assert!(!c.regs.tx_pending, "not retried");
    assert_eq!(attempt(&mut c, &mut s, Fault::None), TxAttempt::Idle);
    // The next frame goes out normally.
    c.xmit(&frame(0x11, &[2])).unwrap();
    assert_eq!(
        attempt(&mut c, &mut s, Fault::None),
        TxAttempt::Sent(frame(0x11, &[2]))
    );
    assert_eq!(s.tx_done, 1);
}

#[test]
fn listen_only_and_presume_ack_set_the_mode_register() {
    let mut c = running(ctrlmode::LISTENONLY);
    assert_eq!(c.regs.mode & (mode::RM | mode::LOM), mode::LOM);
    assert!(!c.regs.acks(), "a listen-only chip acknowledges nothing");
    // It receives.
    assert!(c.regs.deliver(&frame(0x5, &[1])));
    let mut c = running(ctrlmode::PRESUME_ACK);
    assert_eq!(c.regs.mode & (mode::RM | mode::STM), mode::STM);
    // Alone on the bus: the frame goes out without an acknowledgement.
    c.xmit(&frame(0x6, &[])).unwrap();
    assert_eq!(
        c.regs.transmit(Fault::None, false),
        TxAttempt::Sent(frame(0x6, &[]))
    );
    // Without presume-ack, alone: no ACK.
    let mut c = running(0);
    c.xmit(&frame(0x6, &[])).unwrap();
    assert_eq!(c.regs.transmit(Fault::None, false), TxAttempt::Failed);
    assert_eq!(c.regs.txerr, 8);
}

/// Loopback (mainline `sja1000`: MOD.STM, CMR.SRR in place of TR): alone
/// on the bus, no acknowledgement needed; the frame goes on the bus and
/// the chip receives it itself, after the transmit interrupt (the echo
/// first, then the frame from the FIFO, as mainline's handler reads IR).
#[test]
fn loopback_self_test_receives_its_own_frame() {
    let mut c = running(ctrlmode::LOOPBACK);
    assert_eq!(c.regs.mode & (mode::RM | mode::STM), mode::STM);
    let mut s = Seen::default();
    let f = frame(0x7A5, &[1, 2, 3]);
    c.xmit(&f).unwrap();
    assert!(c.regs.tx_pending, "SRR transmits like TR");
    assert_eq!(c.regs.transmit(Fault::None, false), TxAttempt::Sent(f));
    irq(&mut c, &mut s);
    assert_eq!((s.tx_done, s.tx_aborted), (1, 0));
    assert_eq!(s.rx, vec![f], "self reception");
    assert_eq!(c.regs.txerr, 0);
    // Extended and remote frames too.
    let e = frame(CAN_EFF_FLAG | 0x1234_5678, &[9; 8]);
    c.xmit(&e).unwrap();
    assert_eq!(attempt(&mut c, &mut s, Fault::None), TxAttempt::Sent(e));
    assert_eq!(s.rx, vec![f, e]);
    // A frame from another node is received as usual.
    assert!(c.regs.deliver(&frame(0x1, &[])));
    irq(&mut c, &mut s);
    assert_eq!(s.rx.len(), 3);
    // Without loopback, TR: no self reception.
    let mut c = running(0);
    let mut s = Seen::default();
    c.xmit(&f).unwrap();
    assert_eq!(attempt(&mut c, &mut s, Fault::None), TxAttempt::Sent(f));
    assert!(s.rx.is_empty() && s.tx_done == 1);
}

/// Loopback with one-shot: SRR with AT, and a failed attempt (a bit
/// error: self-test needs no ACK, but the bus can still fail) is not
/// retried and nothing is received.
#[test]
fn loopback_one_shot_failure_is_not_received() {
    let mut c = running(ctrlmode::LOOPBACK | ctrlmode::ONE_SHOT);
    let mut s = Seen::default();
    c.xmit(&frame(0x10, &[1])).unwrap();
    let a = attempt(
        &mut c,
        &mut s,
        Fault::BusError {
            ecc: ecc::TX_BIT_DATA,
        },
    );
    assert_eq!(a, TxAttempt::Failed);
    assert_eq!((s.tx_done, s.tx_aborted), (0, 1));
    assert!(s.rx.is_empty());
    assert!(!c.regs.tx_pending);
}

/// A classic frame with `len` 8 and `len8_dlc` `l8`.
fn len8(can_id: u32, l8: u8) -> CanFrame {
    let mut f = frame(can_id, &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88]);
    f.len8_dlc = l8;
    f
}

/// cc-len8-dlc on transmission (mainline `can_get_cc_dlc`): with the mode
/// on, `len` 8 and `len8_dlc` 9..15 go into FI's DLC field, with 8 data
/// bytes; anything else sends `len`.
#[test]
fn cc_len8_dlc_transmit() {
    for (modes, l8, want) in [
        (ctrlmode::CC_LEN8_DLC, 9, 9),
        (ctrlmode::CC_LEN8_DLC, 15, 15),
        (ctrlmode::CC_LEN8_DLC, 8, 8),
        (ctrlmode::CC_LEN8_DLC, 16, 8),
        (ctrlmode::CC_LEN8_DLC, 0, 8),
        (0, 12, 8),
    ] {
        let mut c = running(modes);
        c.xmit(&len8(0x123, l8)).unwrap();
        assert_eq!(c.regs.tx[0] & 0x0F, want, "mode {modes:#x} len8_dlc {l8}");
        assert_eq!(
            &c.regs.tx[3..11],
            &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88]
        );
    }
    // len below 8: len8_dlc is ignored.
    let mut c = running(ctrlmode::CC_LEN8_DLC);
    let mut f = frame(0x5, &[1, 2]);
    f.len8_dlc = 12;
    c.xmit(&f).unwrap();
    assert_eq!(c.regs.tx[0] & 0x0F, 2);
    // Remote frames too (mainline: the same rule, no data bytes).
    let mut c = running(ctrlmode::CC_LEN8_DLC);
    let mut r = len8(0x6 | rcan_core::arb::CAN_RTR_FLAG, 13);
    r.data = [0; 8];
    c.xmit(&r).unwrap();
    assert_eq!(c.regs.tx[0], 0x40 | 13);
}

/// DLC 9..15 across the bus between two chips, and on reception
/// (mainline `can_frame_set_cc_len`): with the mode on, `len` 8 and
/// `len8_dlc` the DLC; with it off, `len` 8 and `len8_dlc` 0.
#[test]
fn cc_len8_dlc_both_ways() {
    for l8 in 9..=15u8 {
        let mut tx = running(ctrlmode::CC_LEN8_DLC);
        let mut s = Seen::default();
        let f = len8(CAN_EFF_FLAG | 0x1ABC_DEF0, l8);
        tx.xmit(&f).unwrap();
        let TxAttempt::Sent(on_bus) = attempt(&mut tx, &mut s, Fault::None) else {
            panic!("not sent");
        };
        assert_eq!(on_bus, f, "the DLC travels on the bus");
        for (modes, want) in [(ctrlmode::CC_LEN8_DLC, l8), (0, 0)] {
            let mut rx = running(modes);
            let mut r = Seen::default();
            assert!(rx.regs.deliver(&on_bus));
            irq(&mut rx, &mut r);
            assert_eq!(r.rx.len(), 1);
            let g = r.rx[0];
            assert_eq!((g.len, g.len8_dlc), (8, want), "mode {modes:#x}");
            assert_eq!(g.data, f.data);
            assert_eq!(g.can_id, f.can_id);
        }
    }
    // A DLC of 8 or less never sets len8_dlc.
    let mut rx = running(ctrlmode::CC_LEN8_DLC);
    let mut r = Seen::default();
    assert!(rx.regs.deliver(&frame(0x1, &[1; 8])));
    irq(&mut rx, &mut r);
    assert_eq!(r.rx[0].len8_dlc, 0);
}

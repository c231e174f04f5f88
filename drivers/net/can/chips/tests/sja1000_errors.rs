// SPDX-License-Identifier: GPL-2.0
//! The SJA1000's error interrupt decoder (`sja1000::sja1000_error`)
//! against mainline's `sja1000_err()`: the error frames' expected bytes,
//! states and counters are worked out by hand from mainline's
//! sja1000_err()/can_change_state() and <linux/can/error.h>, not from our
//! code.

use rcan_chips::sja1000::{irq, sja1000_error, status, Sja1000Err, Sja1000ErrRegs};
use rcan_core::arb::CAN_ERR_FLAG;
use rcan_core::candev::*;

fn sja(
    state: &mut CanState,
    stats: &mut CanStats,
    net: &mut NetErrStats,
    r: Sja1000ErrRegs,
) -> Sja1000Err {
    sja1000_error(state, stats, net, &r)
}

#[test]
fn sja1000_bus_errors() {
    let (mut st, mut stats, mut net) = (
        CanState::ErrorActive,
        CanStats::default(),
        NetErrStats::default(),
    );
    // Form error while receiving, in the data field (ECC 0x40 | DIR | 0x0A).
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::BEI,
            rxerr: 1,
            ecc: 0x6A,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.can_id, CAN_ERR_FLAG | 0x200 | 0x08 | 0x80);
    assert_eq!(e.frame.len, 8);
    assert_eq!(e.frame.data, [0, 0, 0x02, 0x0A, 0, 0, 0, 1]);
    assert!(!e.bus_off);
    assert_eq!((stats.bus_error, net.rx_errors, net.tx_errors), (1, 1, 0));
    // Bit error while transmitting, in the ACK slot (ECC 0x19): PROT_TX.
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::BEI,
            txerr: 8,
            ecc: 0x19,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.data, [0, 0, 0x81, 0x19, 0, 0, 8, 0]);
    assert_eq!((stats.bus_error, net.tx_errors), (2, 1));
    // "Other" error type: no type bit, still the location.
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::BEI,
            ecc: 0xE8,
            ..Default::default()
        },
    );
    assert_eq!((e.frame.data[2], e.frame.data[3]), (0, 0x08));
    assert_eq!(st, CanState::ErrorActive);
}

#[test]
fn sja1000_states_to_bus_off_and_back() {
    let (mut st, mut stats, mut net) = (
        CanState::ErrorActive,
        CanStats::default(),
        NetErrStats::default(),
    );
    // Warning on the TX side.
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::EI,
            sr: status::ES,
            txerr: 100,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.can_id, CAN_ERR_FLAG | 0x200 | 0x04);
    assert_eq!(e.frame.data, [0, 0x08, 0, 0, 0, 0, 100, 0]);
    assert_eq!(st, CanState::ErrorWarning);
    // Passive, both counters equal: both sides reported.
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::EPI,
            sr: status::ES,
            txerr: 130,
            rxerr: 130,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.data[1], 0x30);
    assert_eq!(st, CanState::ErrorPassive);
    // Bus-off: no counters in the frame.
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::EI,
            sr: status::BS | status::ES,
            txerr: 255,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.can_id, CAN_ERR_FLAG | 0x40);
    assert_eq!(e.frame.data, [0; 8]);
    assert!(e.bus_off);
    assert_eq!(st, CanState::BusOff);
    assert_eq!(
        (stats.error_warning, stats.error_passive, stats.bus_off),
        (1, 1, 1)
    );
    // After a restart the driver sets the state back to active; an EPI
    // while passive means "left passive": warning, not counted.
    st = CanState::ErrorPassive;
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::EPI,
            sr: status::ES,
            txerr: 120,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.data[1], 0x08);
    assert_eq!(st, CanState::ErrorWarning);
    assert_eq!(stats.error_warning, 1);
    // Back to active: CRTL_ACTIVE.
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::EI,
            ..Default::default()
        },
    );
    assert_eq!(
        (e.frame.can_id, e.frame.data[1]),
        (CAN_ERR_FLAG | 0x200 | 0x04, 0x40)
    );
    assert_eq!(st, CanState::ErrorActive);
}

#[test]
fn sja1000_overrun_and_arbitration() {
    let (mut st, mut stats, mut net) = (
        CanState::ErrorActive,
        CanStats::default(),
        NetErrStats::default(),
    );
    let e = sja(
        &mut st,
        &mut stats,
        &mut net,
        Sja1000ErrRegs {
            ir: irq::DOI | irq::ALI,
            alc: 0x35,
            ..Default::default()
        },
    );
    assert_eq!(e.frame.can_id, CAN_ERR_FLAG | 0x200 | 0x04 | 0x02);
    assert_eq!(e.frame.data, [0x15, 0x01, 0, 0, 0, 0, 0, 0]);
    assert_eq!(
        (net.rx_over_errors, net.rx_errors, stats.arbitration_lost),
        (1, 1, 1)
    );
}

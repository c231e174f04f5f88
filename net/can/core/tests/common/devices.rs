// SPDX-License-Identifier: GPL-2.0
//! The devices the device-layer tests (`candev.rs`, `candev_fd.rs`) set
//! up, with each controller's limits, clock and control modes as the
//! drivers announce them.
#![allow(dead_code)]

use rcan_core::bittiming::{
    CTUCANFD_DATA_CONST, CTUCANFD_NOMINAL_CONST, I82527_BITTIMING_CONST, SJA1000_BITTIMING_CONST,
};
use rcan_core::candev::*;

/// An SJA1000 at the Kvaser card's 8 MHz (16 MHz crystal).
pub const SJA: Device = Device {
    btc: Some(&SJA1000_BITTIMING_CONST),
    dbtc: None,
    clock_hz: 8_000_000,
    ctrlmode_supported: SJA1000_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: true,
};

/// An 82527 at 8 MHz.
pub const I82527: Device = Device {
    btc: Some(&I82527_BITTIMING_CONST),
    dbtc: None,
    clock_hz: 8_000_000,
    ctrlmode_supported: I82527_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: true,
};

/// A CTU CAN FD core at the PCI card's 100 MHz.
pub const CTU: Device = Device {
    btc: Some(&CTUCANFD_NOMINAL_CONST),
    dbtc: Some(&CTUCANFD_DATA_CONST),
    clock_hz: 100_000_000,
    ctrlmode_supported: CTUCANFD_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: false,
};

// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Lifetimes not tied to anything":
//! `CanDev::arm_restart(&self, dev)` took any device): a driver arms the
//! `restart-ms` timer of one device's `CanDev` with another device. The
//! timer lives as long as the first device and calls the second's restart
//! at bus-off, after the second may have been unregistered and freed.
//! Now `CanDev::arm_restart` takes the device alone, finds its `CanDev`
//! in the device's own private data, and is private to `glue::can`:
//! only `ctrl::open` arms, for the device it opens.
// expect: E0599 no method named `arm_restart` found
#![forbid(unsafe_code)]

use crate::glue::can::dev::{CanDev, CanDevice};
use crate::glue::netdev::Dev;
use kernel::prelude::*;

pub(crate) fn arm_for_other<T: CanDevice>(mine: &CanDev, other: &Dev<T>) -> Result {
    mine.arm_restart(other)
}

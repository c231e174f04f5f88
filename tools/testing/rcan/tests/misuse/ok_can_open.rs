// SPDX-License-Identifier: GPL-2.0
//! Control: a CAN controller driver's `open` and `stop` through
//! `ctrl::open` (which arms the `restart-ms` timer in the device's own
//! `CanDev`) and `ctrl::stop` (which disarms it), as the SJA1000, 82527
//! and CTU CAN FD cores do. If this fails, `restart_other_dev` and
//! `open_other_priv` mean nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::can::ctrl;
use crate::glue::can::dev::CanDevice;
use crate::glue::netdev::Dev;
use kernel::prelude::*;

pub(crate) fn open<T: CanDevice>(dev: &Dev<T>, irq: u32) -> Result {
    let (_settings, opening) = ctrl::open(dev, irq)?;
    // The chip would be programmed and started here.
    opening.up();
    Ok(())
}

pub(crate) fn stop<T: CanDevice>(dev: &Dev<T>) {
    ctrl::stop(dev, || (), || None);
}

// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Lifetimes not tied to anything", the same finding
//! as `restart_other_dev` through `ctrl::open(dev, priv, irq)`, which
//! armed the restart timer of the `CanDev` in `priv` with `dev`): a
//! driver opens one device with another device's private data; the
//! second device's timer then restarts the first, whose lifetime it does
//! not follow. Now `ctrl::open` takes the device alone and finds its
//! `CanDev` in the device's own private data.
// expect: E0061 takes 2 arguments but 3 arguments were supplied
#![forbid(unsafe_code)]

use crate::glue::can::ctrl;
use crate::glue::can::dev::CanDevice;
use crate::glue::netdev::Dev;
use kernel::prelude::*;

pub(crate) fn open_with_other<T: CanDevice>(dev: &Dev<T>, other: &T::Priv) -> Result {
    let (_settings, opening) = ctrl::open(dev, other, 0)?;
    opening.up();
    Ok(())
}

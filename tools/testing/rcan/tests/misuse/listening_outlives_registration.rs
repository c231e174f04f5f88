// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Teardown order left to field order": a `Listening`
//! must be dropped before the device `Registration` it watches, which only
//! the declaration order of a driver's fields guaranteed): a driver keeps
//! the listener and drops the registration (or declares the two fields
//! the other way round). `unregister_netdev` and `free_netdev` free the
//! device while pf_can still calls the listener's trampoline with it: the
//! next bind on any CAN interface reads the freed `net_device`. Now the
//! listening owns the registration (`Listening::new` takes it by value,
//! and its `Drop` removes the listener before the registration goes).
// expect: E0308 mismatched types
#![forbid(unsafe_code)]

use crate::glue::can::proto::{FilterListener, Listening};
use crate::glue::netdev::Registration;
use kernel::prelude::*;

pub(crate) fn unregister_but_listen<T: FilterListener>(
    reg: Registration<T>,
) -> Result<Listening<T>> {
    let listen = Listening::new(&reg)?;
    drop(reg);
    Ok(listen)
}

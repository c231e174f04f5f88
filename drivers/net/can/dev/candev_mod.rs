// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_dev`: the `module!` declaration and what the
//! module compiles in. The module itself is [`candev`] (`candev.rs`),
//! under `#![forbid(unsafe_code)]`; the rtnetlink callbacks are glue
//! (`rust/glue/can/link.rs`, compiled here only), the ops table and its
//! policy are in `candev_c.c`.

use kernel::prelude::*;

#[path = "candev.rs"]
mod candev;
#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../../rust/glue/can/link.rs"]
mod link;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

use candev::CanDevModule;

module! {
    type: CanDevModule,
    name: "rcan_dev",
    author: "rcan developers",
    description: "CAN device layer: the rtnetlink link kind can",
    license: "GPL",
}

// SPDX-License-Identifier: GPL-2.0

//! The pure controller logic of the drivers (crate `rcan-chips`,
//! `drivers/net/can/chips/lib.rs`: each chip's `chip.rs`, the SJA1000's
//! and 82527's `model.rs` for their simulated cards, the SJA1000's
//! `boards.rs`), compiled into a driver module. The files are
//! allocation-free `no_std` Rust with no `unsafe`, host-tested by `cargo
//! test -p rcan-chips`; they name the device layer's pure modules as
//! `super::<name>`, re-exported here from [`rcan_core`](crate::rcan_core)
//! as the host crate does.
#![forbid(unsafe_code)]
// unused_imports: not every driver uses every re-exported module.
#![allow(dead_code, unreachable_pub, missing_docs, unused_imports)]

pub(crate) use crate::rcan_core::{arb, bittiming, candev, filter, frame, rxtable};

#[path = "ctucanfd/chip.rs"]
pub(crate) mod ctucanfd;
#[path = "ctucanfd/model.rs"]
pub(crate) mod ctucanfd_model;
#[path = "i82527/chip.rs"]
pub(crate) mod i82527;
#[path = "i82527/model.rs"]
pub(crate) mod i82527_model;
#[path = "chips/sim_bus.rs"]
pub(crate) mod sim_bus;
#[path = "sja1000/chip.rs"]
pub(crate) mod sja1000;
#[path = "sja1000/boards.rs"]
pub(crate) mod sja1000_boards;
#[path = "sja1000/model.rs"]
pub(crate) mod sja1000_model;

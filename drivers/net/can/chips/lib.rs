// SPDX-License-Identifier: GPL-2.0
//! The pure controller logic of the rcan CAN drivers, host-tested: for
//! each chip its register programming and frame (de)coding (`chip.rs`)
//! and a register-level model of it (`model.rs`) that the host tests and
//! the simulated cards drive, in the chip's own driver directory
//! (`drivers/net/can/<chip>/`); the SJA1000's board-specific parts
//! (`sja1000/boards.rs`) beside them.
//!
//! Each file is allocation-free `no_std` Rust with no `unsafe`, as in
//! `net/can/core` (crate `rcan-core`), whose modules it names as
//! `super::<name>`: this crate re-exports them at its root, and the
//! kernel's `drivers/net/can/rcan_chips.rs` does the same, so the same
//! files compile in both. The device layer's generic rules (bit timing,
//! `ip link` validation, error states and frames) stay in `rcan-core`.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub use rcan_core::{arb, bittiming, candev, filter, frame, rxtable};

#[path = "../ctucanfd/chip.rs"]
pub mod ctucanfd;
#[path = "../ctucanfd/model.rs"]
pub mod ctucanfd_model;
#[path = "../i82527/chip.rs"]
pub mod i82527;
#[path = "../i82527/model.rs"]
pub mod i82527_model;
pub mod sim_bus;
#[path = "../sja1000/chip.rs"]
pub mod sja1000;
#[path = "../sja1000/boards.rs"]
pub mod sja1000_boards;
#[path = "../sja1000/model.rs"]
pub mod sja1000_model;

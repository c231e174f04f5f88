// SPDX-License-Identifier: GPL-2.0
//! The register-level SJA1000 model the tests drive the driver core
//! against: the core's own (`rcan_chips::sja1000_model`), which the
//! kernel's simulated card (`rcan_sja1000_sim`) runs too.
#[allow(unused_imports)]
pub use rcan_chips::sja1000_model::*;

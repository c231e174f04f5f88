// SPDX-License-Identifier: GPL-2.0
//! Shared test models (not every test uses every item).
#![allow(dead_code)]
pub mod filters;
pub mod sja1000_model;

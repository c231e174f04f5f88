// SPDX-License-Identifier: GPL-2.0
//! Fuzz the DSOR receive path (coverage-guided); the check itself is in
//! `../dsor_rx_check.rs`, which the host test `tests/dsor_rx_fuzz_replay.rs`
//! also runs.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../dsor_rx_check.rs"]
mod dsor_rx_check;

fuzz_target!(|input: &[u8]| dsor_rx_check::check(input));

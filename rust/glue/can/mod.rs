// SPDX-License-Identifier: GPL-2.0

//! The CAN framework the protocols and drivers build on.
//!
//! * [`rx`]: the incremental receive table of `rcan_pf`.

pub(crate) mod rx;

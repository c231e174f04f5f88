// SPDX-License-Identifier: GPL-2.0

//! The CAN framework the protocols and drivers build on.
//!
//! * [`proto`]: the typed protocol framework (protocol registration,
//!   receive subscriptions, in-kernel receivers, filter listeners,
//!   sending) that protocols and drivers use.
//! * [`abi`]: the C ABI between the modules underneath it.
//! * [`rx`]: the incremental receive table of `rcan_pf`.
//! * [`skb`]: the one place a CAN skb (classic or CAN FD) is built.
//! * [`dev`]: the CAN device layer, drivers' side (`CanDevice`), and the
//!   C ABI to `rcan_dev`, which registers the "can" link kind (its
//!   rtnetlink callbacks are `link.rs`, compiled into `rcan_dev` only).
//! * [`ctrl`]: what the controller drivers share around their chips
//!   (device setup, open/stop, received frames, echoes, statistics).
//!
//! `family.rs` (the PF_CAN family and the C entry points `rcan_pf`
//! exports) is compiled into `rcan_pf` only, by `pf_can_mod.rs`.

pub(crate) mod abi;
pub(crate) mod ctrl;
pub(crate) mod dev;
pub(crate) mod proto;
pub(crate) mod rx;
pub(crate) mod skb;

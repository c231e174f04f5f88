// SPDX-License-Identifier: GPL-2.0

//! The pure, host-tested logic of `net/can/core` (crate `rcan-core`),
//! compiled into a kernel module. Each file is allocation-free `no_std` Rust
//! with no `unsafe`; `cargo test -p rcan-core` tests the same files.
#![forbid(unsafe_code)]
#![allow(dead_code, unreachable_pub, missing_docs)]

#[path = "core/src/arb.rs"]
pub(crate) mod arb;
#[path = "core/src/bcm.rs"]
pub(crate) mod bcm;
#[path = "core/src/bcm_rx.rs"]
pub(crate) mod bcm_rx;
#[path = "core/src/bcm_tx.rs"]
pub(crate) mod bcm_tx;
#[path = "core/src/bittiming.rs"]
pub(crate) mod bittiming;
#[path = "core/src/candev.rs"]
pub(crate) mod candev;
#[path = "core/src/canloop.rs"]
pub(crate) mod canloop;
#[path = "core/src/dsor_addr.rs"]
pub(crate) mod dsor_addr;
#[path = "core/src/dsor_fd.rs"]
pub(crate) mod dsor_fd;
#[path = "core/src/dsor_rx.rs"]
pub(crate) mod dsor_rx;
#[path = "core/src/dsor_tx.rs"]
pub(crate) mod dsor_tx;
#[path = "core/src/dsor_udp.rs"]
pub(crate) mod dsor_udp;
#[path = "core/src/dsor_wire.rs"]
pub(crate) mod dsor_wire;
#[path = "core/src/filter.rs"]
pub(crate) mod filter;
#[path = "core/src/frame.rs"]
pub(crate) mod frame;
#[path = "core/src/isotp.rs"]
pub(crate) mod isotp;
#[path = "core/src/isotp_pci.rs"]
pub(crate) mod isotp_pci;
#[path = "core/src/isotp_rx.rs"]
pub(crate) mod isotp_rx;
#[path = "core/src/isotp_tx.rs"]
pub(crate) mod isotp_tx;
#[path = "core/src/j1939.rs"]
pub(crate) mod j1939;
#[path = "core/src/j1939_ac.rs"]
pub(crate) mod j1939_ac;
#[path = "core/src/j1939_errqueue.rs"]
pub(crate) mod j1939_errqueue;
#[path = "core/src/j1939_tp.rs"]
pub(crate) mod j1939_tp;
#[path = "core/src/j1939_tp_rx.rs"]
pub(crate) mod j1939_tp_rx;
#[path = "core/src/j1939_tp_tx.rs"]
pub(crate) mod j1939_tp_tx;
#[path = "core/src/ring.rs"]
pub(crate) mod ring;
#[path = "core/src/rxtable.rs"]
pub(crate) mod rxtable;
#[path = "core/src/slotring.rs"]
pub(crate) mod slotring;
#[path = "core/src/sockaddr.rs"]
pub(crate) mod sockaddr;
#[path = "core/src/timesvc.rs"]
pub(crate) mod timesvc;

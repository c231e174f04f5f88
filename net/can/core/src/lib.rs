// SPDX-License-Identifier: GPL-2.0
//! Host-testable core logic of the rcan CAN stack (thesis chapter 5).
//!
//! Every module below is also compiled into the kernel modules through
//! `#[path = ".../net/can/core/src/<name>.rs"] mod <name>;`, so each file is
//! `no_std`, allocation-free and `unsafe`-free, and refers to its siblings
//! only as `super::<name>`.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod arb;
pub mod bcm;
pub mod bcm_rx;
pub mod bcm_tx;
pub mod bittiming;
pub mod candev;
pub mod canloop;
pub mod dsor_addr;
pub mod dsor_fd;
pub mod dsor_rx;
pub mod dsor_tx;
pub mod dsor_udp;
pub mod dsor_wire;
pub mod filter;
pub mod frame;
pub mod isotp;
pub mod isotp_pci;
pub mod isotp_rx;
pub mod isotp_tx;
pub mod j1939;
pub mod j1939_ac;
pub mod j1939_echo;
pub mod j1939_errqueue;
pub mod j1939_tp;
pub mod j1939_tp_rx;
pub mod j1939_tp_tx;
pub mod ring;
pub mod rxtable;
pub mod slotring;
pub mod sockaddr;
pub mod timesvc;

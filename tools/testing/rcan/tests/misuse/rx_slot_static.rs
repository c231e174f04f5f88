// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Teardown duties left to safe code": a
//! protocol-supplied `static` `RxSlot` lets two sockets share one
//! receiver handle under different socket locks): `CanProtocol::rx_slot`
//! let the protocol say where a socket's reserved receiver is kept, and
//! nothing stopped it from answering with one static for every socket, so
//! one socket's `rx_release` freed the receiver another one still used.
//! The glue now keeps the slot in the sock object; the protocol only says
//! whether it wants one (`RESERVE_RX`), so there is no slot to hand out.
// expect: E0432 unresolved import `crate::glue::can::proto::RxSlot`
#![forbid(unsafe_code)]

use crate::glue::can::proto::RxSlot;

static EVERY_SOCKET: RxSlot = RxSlot::new();

pub(crate) fn rx_slot<S>(_shared: &S) -> Option<&RxSlot> {
    Some(&EVERY_SOCKET)
}

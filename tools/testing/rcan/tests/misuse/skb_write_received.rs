// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "`&mut Skb` is taken to mean \"not shared\""): a
//! protocol's receive callback takes its own reference to the frame
//! (`RxSkb::into_owned`: pf_can's reference, or a clone sharing the data
//! with every other receiver and, on a device without IFF_ECHO, with the
//! skb being transmitted) and writes the frame's bytes, racing another
//! socket's recvmsg and the driver's start_xmit.
// expect: E0599 no method named `data_mut` found
#![forbid(unsafe_code)]

use crate::glue::can::proto::RxSkb;

pub(crate) fn rx(skb: RxSkb<'_>) {
    if let Some(mut skb) = skb.into_owned() {
        skb.data_mut()[0] = 0x7f;
    }
}

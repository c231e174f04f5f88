// SPDX-License-Identifier: GPL-2.0

//! rcan_dev: the CAN device layer (mainline's `can-dev`), the module that
//! owns the rtnetlink link kind "can" so that `ip link set canX type can
//! bitrate ...` and `ip -details link show canX` work on rcan's CAN
//! controllers. The attribute handling is glue (`link.rs`), the rules are
//! `rcan_core::candev`, and each driver answers through its
//! `glue::can::dev::CanDevice` implementation. See
//! Documentation/networking/rcan/can-dev.rst.
//!
//! Only one module can own a link kind: while mainline's `can-dev` is
//! loaded the registration fails with `EEXIST`, and so does loading this
//! module (with a kernel log line saying why), never anything worse.
//! Context: init and exit run in process context.
#![forbid(unsafe_code)]

use crate::link::LinkKind;
use kernel::prelude::*;

pub(crate) struct CanDevModule {
    _kind: LinkKind,
}

impl kernel::Module for CanDevModule {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        match LinkKind::register() {
            Ok(kind) => Ok(CanDevModule { _kind: kind }),
            Err(e) => {
                if e == EEXIST {
                    pr_err!(
                        "the rtnetlink link kind \"can\" is taken (mainline can-dev loaded?): \
                         unload it (rmmod can-dev and its drivers) before rcan_dev\n"
                    );
                } else {
                    pr_err!("cannot register the link kind \"can\": {:?}\n", e);
                }
                Err(e)
            }
        }
    }
}

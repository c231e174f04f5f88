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
//!
//! Module parameter `rtnl_link` (default Y): with N the module loads
//! without registering the kind, so that mainline's `can-dev` and its
//! drivers can be loaded beside rcan's (the CTU CAN FD wire-peer test).
//! rcan's devices keep pointing to the (unregistered) ops: `ip -details
//! link show` still prints their settings, while rtnetlink, which finds a
//! kind only among registered ones, refuses `ip link set canX type can
//! ...` on them with `EOPNOTSUPP` and never hands them to another
//! module's `changelink` (it compares the kind's ops with the device's).
//! Context: init and exit run in process context.
#![forbid(unsafe_code)]

use crate::glue::params::Param;
use crate::link::LinkKind;
use kernel::prelude::*;

/// Module parameter `rtnl_link` (number 0 in candev_c.c, read-only).
const RTNL_LINK: Param<bool> = Param::new(0);

pub(crate) struct CanDevModule {
    /// `None` with `rtnl_link=N`.
    _kind: Option<LinkKind>,
}

impl kernel::Module for CanDevModule {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        if !RTNL_LINK.get() {
            pr_info!(
                "rtnl_link=N: the link kind \"can\" is not registered; \
                 rcan devices take their bit timing from module parameters\n"
            );
            return Ok(CanDevModule { _kind: None });
        }
        match LinkKind::register() {
            Ok(kind) => Ok(CanDevModule { _kind: Some(kind) }),
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

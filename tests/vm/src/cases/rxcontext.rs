// SPDX-License-Identifier: GPL-2.0
//! Receivers never run with hard interrupts off (issue 20 item 2): the
//! exact sequence of the outside probe. With the stack loaded,
//! `rcan_dsor ifname=can0` and `rcan_i82527_sim cards=2`, `cansend can1
//! 00000123#1122` (an extended frame whose DSOR destination is node 0)
//! reaches DSOR's receiver twice: as can1's echo and as can2's bus frame.
//! The simulated 82527 card used to hand both to the receivers under its
//! chip lock with interrupts off, and DSOR's `spin_lock_bh` made the debug
//! kernel warn (`__local_bh_enable_ip`, lockdep); the VM runner fails the
//! run on such a report. The frame must also arrive, on can2 and as can1's
//! echo, on both kernels.

use super::test_table;
use crate::canraw::{self, ext};
use crate::check::TestResult;
use crate::ctx::{Ctx, Module};
use crate::tools;
use crate::Test;

pub const TESTS: &[Test] = test_table![i82527_dsor_rx_context];

fn i82527_dsor_rx_context(ctx: &mut Ctx) -> TestResult {
    // The stack (rcan_loop's can0 is up), DSOR on can0, then the cards:
    // can1 and can2.
    ctx.load_stack(&[])?;
    ctx.insmod(Module::Dsor, &["ifname=can0"])?;
    ctx.insmod(Module::I82527Sim, &["cards=2"])?;
    ctx.link_up("can1")?;
    ctx.link_up("can2")?;
    let (i1, i2) = (ctx.ifindex("can1")?, ctx.ifindex("can2")?);
    let on_bus = canraw::open(i2)?;
    let echo = canraw::open(i1)?;
    tools::run_ok("cansend", &["can1", "00000123#1122"])?;
    let want = ext(0x123, &[0x11, 0x22]);
    canraw::expect(&on_bus, &want, "CAN_RAW socket on can2 (the bus)")?;
    canraw::expect(&echo, &want, "CAN_RAW socket on can1 (the echo)")
}

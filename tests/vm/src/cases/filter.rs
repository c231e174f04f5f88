// SPDX-License-Identifier: GPL-2.0
//! Acceptance filters (arb, mask; 1 bits = don't care) and interface
//! selection by ifindex.

use rcan_uapi::{arb_std, CAN_ARB_EXT_BITS, CAN_IDE, CAN_MASK_ANY, CAN_MASK_EXACT, CAN_RTR};

use super::{stack1, stack2, test_table};
use crate::check::{ensure, expect_frame, expect_none, recv_frame, Frame, OrFail, TestResult};
use crate::ctx::{dev, Ctx};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    filter_rtr_must_match,
    filter_mask_any,
    ;
    stack:
    filter_exact_std,
    filter_exact_ext,
    filter_ide_dont_care,
    filter_rtr_dont_care,
    filter_id_range,
    filter_unbound_receives_nothing,
    filter_rebind_replaces,
    ifindex_bound_interface_only,
    ifindex_zero_receives_all,
    ifindex_zero_sends_on_all,
    ifindex_zero_skips_down,
];

/// Binds a socket to (`arb`, `mask`) on can0, sends every frame of `cases`
/// (frame, should it pass), and checks that exactly the passing ones arrive,
/// in order. Frames are delivered in order, so a wrongly accepted frame
/// shows up in place of the next expected one.
fn check_filter(ctx: &mut Ctx, arb: u32, mask: u32, cases: &[(Frame, bool)]) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(arb, mask, idx)?;
    let tx = ctx.socket()?;
    for (f, _) in cases {
        f.send(&tx, idx)?;
    }
    for (f, _) in cases.iter().filter(|(_, pass)| *pass) {
        expect_frame(&rx, f, idx)
            .map_err(|e| format!("filter arb {arb:#010x} mask {mask:#010x}: {e}"))?;
    }
    expect_none(&[&rx]).map_err(|e| format!("filter arb {arb:#010x} mask {mask:#010x}: {e}"))
}

/// Exact standard identifier: other ids, extended frames with the same top
/// bits and remote frames of the id are rejected.
fn filter_exact_std(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (Frame::std(0x124, &[1]), false),
        (Frame::ext(0x123 << 18, &[2]), false),
        (Frame::remote_std(0x123, 1), false),
        (Frame::std(0x123, &[3]), true),
        (Frame::std(0x122, &[4]), false),
        (Frame::std(0x523, &[5]), false),
        (Frame::std(0x123, &[]), true),
    ];
    check_filter(ctx, arb_std(0x123, false), CAN_MASK_EXACT, &cases)
}

/// Exact extended identifier: a standard frame whose id equals the top 11
/// bits must not arrive, nor a neighbouring extended id.
fn filter_exact_ext(ctx: &mut Ctx) -> TestResult {
    let id = 0x1ABC_DEF0;
    let cases = [
        (Frame::std(id >> 18, &[1]), false),
        (Frame::ext(id + 1, &[2]), false),
        (Frame::ext(id ^ 0x0400_0000, &[3]), false),
        (Frame::remote_ext(id, 2), false),
        (Frame::ext(id, &[4, 4]), true),
        (Frame::ext(id ^ 0x8, &[5]), false),
        (Frame::ext(id, &[6; 8]), true),
    ];
    check_filter(ctx, Frame::ext(id, &[]).arb, CAN_MASK_EXACT, &cases)
}

/// IDE and extension bits don't care: standard id X and extended frames
/// whose top 11 bits are X both arrive; other ids and remote frames do not.
fn filter_ide_dont_care(ctx: &mut Ctx) -> TestResult {
    let x = 0x3C5;
    let cases = [
        (Frame::std(x, &[1]), true),
        (Frame::ext(x << 18, &[2]), true),
        (Frame::ext((x << 18) | 0x2_ABCD, &[3]), true),
        (Frame::ext((x << 18) | 0x3_FFFF, &[]), true),
        (Frame::std(x + 1, &[4]), false),
        (Frame::ext((x + 1) << 18, &[5]), false),
        (Frame::remote_std(x, 2), false),
        (Frame::remote_ext(x << 18, 2), false),
        (Frame::std(x, &[6]), true),
    ];
    check_filter(
        ctx,
        arb_std(x, false),
        CAN_IDE | CAN_ARB_EXT_BITS | 1,
        &cases,
    )
}

/// RTR don't care: data and remote frames of the id arrive.
fn filter_rtr_dont_care(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (Frame::std(0x55, &[1]), true),
        (Frame::remote_std(0x55, 3), true),
        (Frame::remote_std(0x56, 3), false),
        (Frame::std(0x54, &[2]), false),
        (Frame::remote_std(0x55, 0), true),
        (Frame::std(0x55, &[3]), true),
    ];
    check_filter(ctx, arb_std(0x55, false), CAN_RTR | 1, &cases)
}

/// RTR must match: a data-frame filter takes only data frames, and a
/// remote-frame filter only remote frames.
fn filter_rtr_must_match(ctx: &mut Ctx) -> TestResult {
    let data = [
        (Frame::remote_std(0x66, 8), false),
        (Frame::std(0x66, &[1]), true),
        (Frame::remote_std(0x66, 1), false),
        (Frame::std(0x66, &[2]), true),
    ];
    check_filter(ctx, arb_std(0x66, false), CAN_MASK_EXACT, &data)?;
    ctx.unload_all()?;
    let remote = [
        (Frame::std(0x66, &[1]), false),
        (Frame::remote_std(0x66, 8), true),
        (Frame::std(0x66, &[2]), false),
        (Frame::remote_ext(0x66 << 18, 1), false),
        (Frame::remote_std(0x66, 1), true),
    ];
    check_filter(ctx, arb_std(0x66, true), CAN_MASK_EXACT, &remote)
}

/// Don't-care low identifier bits select a range: 0x120..=0x12F.
fn filter_id_range(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (Frame::std(0x11F, &[1]), false),
        (Frame::std(0x120, &[2]), true),
        (Frame::std(0x12F, &[3]), true),
        (Frame::std(0x130, &[4]), false),
        (Frame::std(0x127, &[5]), true),
        (Frame::ext(0x127 << 18, &[6]), false),
    ];
    check_filter(ctx, arb_std(0x120, false), arb_std(0xF, false) | 1, &cases)
}

/// Mask all ones: every frame arrives.
fn filter_mask_any(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (Frame::std(0, &[]), true),
        (Frame::std(0x7FF, &[1; 8]), true),
        (Frame::ext(0, &[2]), true),
        (Frame::ext(0x1FFF_FFFF, &[3; 8]), true),
        (Frame::remote_std(0x400, 4), true),
        (Frame::remote_ext(0x1000_0000, 8), true),
    ];
    check_filter(ctx, 0, CAN_MASK_ANY, &cases)?;
    ctx.unload_all()?;
    // The pattern does not matter when every bit is don't care.
    check_filter(ctx, Frame::ext(0x0F0F_0F0F, &[]).arb, CAN_MASK_ANY, &cases)
}

/// A socket that was never bound receives nothing, whatever is sent.
fn filter_unbound_receives_nothing(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let unbound = ctx.socket()?;
    let witness = ctx.bound(0, CAN_MASK_ANY, 0)?;
    let frames = [
        Frame::std(0, &[]),
        Frame::ext(0, &[1]),
        Frame::remote_std(0x7FF, 2),
    ];
    for f in &frames {
        // The unbound socket sends too: it must not see its own frames.
        f.send(&unbound, idx)?;
        f.send(&unbound, 0)?;
    }
    for f in &frames {
        expect_frame(&witness, f, idx)?;
        expect_frame(&witness, f, idx)?;
    }
    expect_none(&[&unbound, &witness])
}

/// Binding again replaces the filter (and getsockname shows the new one).
fn filter_rebind_replaces(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(arb_std(0x100, false), CAN_MASK_EXACT, idx)?;
    let a = Frame::std(0x100, &[0xA]);
    let b = Frame::std(0x200, &[0xB]);
    a.send(&tx, idx)?;
    b.send(&tx, idx)?;
    expect_frame(&rx, &a, idx)?;
    expect_none(&[&rx])?;

    rx.bind(b.arb, CAN_MASK_EXACT, idx).or_fail("rebind")?;
    let la = rx.local_addr().or_fail("getsockname")?;
    ensure!(
        la.arb == b.arb,
        "getsockname after rebind: arb {:#x}",
        la.arb
    );
    a.send(&tx, idx)?;
    b.send(&tx, idx)?;
    expect_frame(&rx, &b, idx)?;
    expect_none(&[&rx])
}

/// count=2: a socket bound to can1 sees can1's frames only.
fn ifindex_bound_interface_only(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = stack2(ctx)?;
    let on1 = ctx.bound(0, CAN_MASK_ANY, i1)?;
    let on0 = ctx.bound(0, CAN_MASK_ANY, i0)?;
    let tx = ctx.socket()?;
    let f0 = Frame::std(0x10, &[0]);
    let f1 = Frame::std(0x11, &[1]);
    f0.send(&tx, i0)?;
    f1.send(&tx, i1)?;
    f0.send(&tx, i0)?;
    expect_frame(&on1, &f1, i1)?;
    expect_frame(&on0, &f0, i0)?;
    expect_frame(&on0, &f0, i0)?;
    expect_none(&[&on1, &on0])
}

/// A socket bound to ifindex 0 sees frames of both interfaces, with the
/// receiving interface in the address.
fn ifindex_zero_receives_all(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = stack2(ctx)?;
    let any = ctx.bound(0, CAN_MASK_ANY, 0)?;
    let tx = ctx.socket()?;
    let f0 = Frame::ext(0x10, &[0]);
    let f1 = Frame::ext(0x11, &[1]);
    f1.send(&tx, i1)?;
    f0.send(&tx, i0)?;
    expect_frame(&any, &f1, i1)?;
    expect_frame(&any, &f0, i0)?;
    expect_none(&[&any])
}

/// sendto ifindex 0 transmits a copy on every interface that is up.
fn ifindex_zero_sends_on_all(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = stack2(ctx)?;
    let on0 = ctx.bound(0, CAN_MASK_ANY, i0)?;
    let on1 = ctx.bound(0, CAN_MASK_ANY, i1)?;
    let any = ctx.bound(0, CAN_MASK_ANY, 0)?;
    let tx = ctx.socket()?;
    let f = Frame::std(0x3AB, &[1, 2, 3]);
    f.send(&tx, 0)?;
    expect_frame(&on0, &f, i0)?;
    expect_frame(&on1, &f, i1)?;
    // The ifindex-0 socket gets one copy per interface, in either order.
    let mut seen = [recv_frame(&any)?, recv_frame(&any)?];
    seen.sort_by_key(|r| r.ifindex);
    let mut want = [i0, i1];
    want.sort_unstable();
    ensure!(
        seen.iter().all(|r| r.frame == f) && [seen[0].ifindex, seen[1].ifindex] == want,
        "ifindex-0 socket: got {} from {} and {} from {}",
        seen[0].frame,
        seen[0].ifindex,
        seen[1].frame,
        seen[1].ifindex
    );
    expect_none(&[&on0, &on1, &any])
}

/// sendto ifindex 0 skips interfaces that are down.
fn ifindex_zero_skips_down(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = stack2(ctx)?;
    ctx.link_down(&dev(1))?;
    let any = ctx.bound(0, CAN_MASK_ANY, 0)?;
    let tx = ctx.socket()?;
    let f = Frame::std(0x1, &[1]);
    f.send(&tx, 0)?;
    expect_frame(&any, &f, i0)?;
    expect_none(&[&any])?;
    ctx.link_up(&dev(1))?;
    ctx.link_down(&dev(0))?;
    f.send(&tx, 0)?;
    expect_frame(&any, &f, i1)?;
    expect_none(&[&any])
}

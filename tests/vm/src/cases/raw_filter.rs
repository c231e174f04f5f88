// SPDX-License-Identifier: GPL-2.0
//! CAN_RAW receive filters: the default filter, exact standard and extended
//! filters, masks, CAN_INV_FILTER, several filters (OR) and
//! CAN_RAW_JOIN_FILTERS (AND), zero filters, and the error mask
//! (CAN_RAW_ERR_FILTER) that selects error frames.
//!
//! Each test sends its frames from a second socket on can0, then a marker
//! frame that must pass, and checks that exactly the passing frames and the
//! marker arrive, in order.

use socketcan::{CanAddr, Socket, SocketOptions};

use super::{portable_table, raw1};
use crate::canraw::{
    self, check_delivery, err_frame, expect, expect_quiet, ext, filters, rtr_ext, rtr_std, std,
    CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_BUSOFF, CAN_ERR_CRTL, CAN_ERR_FLAG, CAN_ERR_MASK,
    CAN_INV_FILTER, CAN_RTR_FLAG, CAN_SFF_MASK,
};
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    raw_filter_join,
    ;
    stack:
    raw_filter_default_all,
    raw_filter_exact_sff,
    raw_filter_exact_eff,
    raw_filter_masked,
    raw_filter_masked_sff_only,
    raw_filter_inverse,
    raw_filter_or,
    raw_filter_none,
    raw_filter_before_bind,
    raw_filter_err_mask,
];

/// Sets `filters` on a socket bound to can0 and checks which of `cases`
/// pass.
fn check_filters(
    ctx: &mut Ctx,
    filters: &[(u32, u32)],
    join: bool,
    cases: &[(socketcan::CanFrame, bool)],
    marker: &socketcan::CanFrame,
) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    rx.set_filters(filters).or_fail("set filters")?;
    rx.set_join_filters(join)
        .or_fail("set CAN_RAW_JOIN_FILTERS")?;
    check_delivery(
        &tx,
        &rx,
        cases,
        marker,
        &format!("filters {filters:08X?} join {join}"),
    )
}

/// The default filter receives every data and remote frame, standard and
/// extended, but no error frame.
fn raw_filter_default_all(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    let cases = [
        (std(0x000, &[]), true),
        (std(0x7FF, &[1, 2, 3, 4, 5, 6, 7, 8]), true),
        (ext(0, &[1]), true),
        (ext(0x1FFF_FFFF, &[2]), true),
        (err_frame(CAN_ERR_BUSOFF, &[]), false),
        (rtr_std(0x123, 4), true),
        (rtr_ext(0x1234_5678, 0), true),
    ];
    check_delivery(&tx, &rx, &cases, &std(0x42, &[0xEE]), "default filter")
}

/// An exact standard filter (id, SFF mask, EFF and RTR flags in the mask)
/// takes only that id as a standard data frame.
fn raw_filter_exact_sff(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (std(0x124, &[1]), false),
        (ext(0x123, &[2]), false),
        (rtr_std(0x123, 1), false),
        (std(0x123, &[3]), true),
        (std(0x523, &[4]), false),
        (ext(0x123 << 18, &[5]), false),
        (std(0x123, &[]), true),
    ];
    let f = [(0x123, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG)];
    check_filters(ctx, &f, false, &cases, &std(0x123, &[0xEE]))
}

/// An exact extended filter takes only that id as an extended data frame,
/// not the standard frame of its low or high bits.
fn raw_filter_exact_eff(ctx: &mut Ctx) -> TestResult {
    let id = 0x1234_5678;
    let cases = [
        (std((id >> 18) as u16, &[1]), false),
        (std((id & 0x7FF) as u16, &[2]), false),
        (ext(id + 1, &[3]), false),
        (rtr_ext(id, 2), false),
        (ext(id, &[4, 4]), true),
        (ext(id ^ 0x1000_0000, &[5]), false),
        (ext(id, &[6; 8]), true),
    ];
    let f = [(
        id | CAN_EFF_FLAG,
        CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
    )];
    check_filters(ctx, &f, false, &cases, &ext(id, &[0xEE]))
}

/// A mask without the EFF and RTR flags compares only the masked id bits:
/// extended frames whose low bits match and remote frames pass too.
fn raw_filter_masked(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (std(0x120, &[1]), true),
        (std(0x12F, &[2]), true),
        (std(0x130, &[3]), false),
        (std(0x220, &[4]), false),
        (ext(0x125, &[5]), true),
        (ext(0x0100_0125, &[6]), true),
        (ext(0x135, &[7]), false),
        (rtr_std(0x121, 2), true),
    ];
    check_filters(ctx, &[(0x120, 0x7F0)], false, &cases, &std(0x12A, &[0xEE]))
}

/// With CAN_EFF_FLAG in the mask but not in the id, the filter takes only
/// standard frames.
fn raw_filter_masked_sff_only(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (std(0x120, &[1]), true),
        (ext(0x125, &[2]), false),
        (std(0x130, &[3]), false),
        (rtr_std(0x121, 2), true),
        (rtr_ext(0x121, 2), false),
        (std(0x12F, &[4]), true),
    ];
    let f = [(0x120, 0x7F0 | CAN_EFF_FLAG)];
    check_filters(ctx, &f, false, &cases, &std(0x12A, &[0xEE]))
}

/// CAN_INV_FILTER: everything whose masked id differs passes; error frames
/// do not.
fn raw_filter_inverse(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (std(0x123, &[1]), false),
        (std(0x124, &[2]), true),
        (ext(0x123, &[3]), false),
        (ext(0x124, &[4]), true),
        (rtr_std(0x123, 1), false),
        (rtr_std(0x7FF, 1), true),
        (err_frame(CAN_ERR_BUSOFF, &[]), false),
        (ext(0x1FFF_F923, &[5]), false),
    ];
    let f = [(0x123 | CAN_INV_FILTER, CAN_SFF_MASK)];
    check_filters(ctx, &f, false, &cases, &std(0x100, &[0xEE]))
}

/// Filter 1xx and filter x2x.
const TWO: [(u32, u32); 2] = [(0x100, 0x700), (0x020, 0x0F0)];

/// Several filters: a frame passes if any filter takes it, and arrives
/// once even if several do.
fn raw_filter_or(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (std(0x123, &[1]), true),
        (std(0x133, &[2]), true),
        (std(0x223, &[3]), true),
        (std(0x233, &[4]), false),
        (std(0x120, &[5]), true),
    ];
    check_filters(ctx, &TWO, false, &cases, &std(0x1FF, &[0xEE]))
}

/// CAN_RAW_JOIN_FILTERS: a frame passes only if every filter takes it, with
/// two and with three filters.
fn raw_filter_join(ctx: &mut Ctx) -> TestResult {
    let cases = [
        (std(0x123, &[1]), true),
        (std(0x133, &[2]), false),
        (std(0x223, &[3]), false),
        (std(0x233, &[4]), false),
        (std(0x120, &[5]), true),
    ];
    check_filters(ctx, &TWO, true, &cases, &std(0x12F, &[0xEE]))?;
    ctx.unload_all()?;
    let three = [TWO[0], TWO[1], (0x003, 0x00F)];
    let cases = [
        (std(0x123, &[1]), true),
        (std(0x120, &[2]), false),
        (std(0x1A3, &[3]), false),
        (std(0x023, &[4]), false),
    ];
    check_filters(ctx, &three, true, &cases, &std(0x123, &[0xEE]))
}

/// Zero filters: nothing arrives and the filter list reads back empty;
/// setting a filter again makes frames arrive.
fn raw_filter_none(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let none = canraw::open(idx)?;
    let all = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    none.set_filter_drop_all().or_fail("set zero filters")?;
    let f = filters(&none)?;
    ensure!(f.is_empty(), "zero filters read back as {f:08X?}");
    let frames = [std(0x000, &[1]), ext(0x1FFF_FFFF, &[2]), rtr_std(0x7FF, 0)];
    for fr in &frames {
        canraw::send(&tx, fr)?;
    }
    // `all` seeing them shows they were delivered.
    canraw::expect_seq(&all, &frames, "socket with the default filter")?;
    expect_quiet(&[("socket with zero filters", &none)])?;
    none.set_filter_accept_all().or_fail("set filter (0, 0)")?;
    let f = std(0x321, &[3]);
    canraw::send(&tx, &f)?;
    expect(&none, &f, "socket after setting a filter again")
}

/// Filters set before bind take effect at bind; an unbound socket receives
/// nothing.
fn raw_filter_before_bind(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::unbound()?;
    let never = canraw::unbound()?;
    let tx = canraw::open(idx)?;
    let all = canraw::open(idx)?;
    s.set_filters(&[(0x321, CAN_SFF_MASK)])
        .or_fail("set filter before bind")?;
    let early = std(0x321, &[1]);
    canraw::send(&tx, &early)?;
    canraw::expect(&all, &early, "bound socket")?;
    s.as_raw_socket()
        .bind(&CanAddr::new(idx).into_sock_addr())
        .or_fail("bind to can0")?;
    expect_quiet(&[
        ("socket bound after the frame was sent", &s),
        ("unbound socket", &never),
    ])?;
    let cases = [
        (std(0x320, &[2]), false),
        (std(0x321, &[3]), true),
        (ext(0x1000, &[4]), false),
    ];
    check_delivery(
        &tx,
        &s,
        &cases,
        &std(0x321, &[0xEE]),
        "filter set before bind",
    )?;
    expect_quiet(&[("unbound socket", &never)])
}

/// Error frames sent on can0 reach exactly the sockets whose error mask
/// has one of the frame's error class bits, even with zero data filters,
/// or with a filter whose mask has CAN_ERR_FLAG and that class; never a
/// socket with the default (zero) error mask.
fn raw_filter_err_mask(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let busoff = canraw::open(idx)?;
    let crtl = canraw::open(idx)?;
    let default = canraw::open(idx)?;
    let only_err = canraw::open(idx)?;
    busoff
        .set_error_filter(CAN_ERR_BUSOFF)
        .or_fail("set CAN_RAW_ERR_FILTER BUSOFF")?;
    crtl.set_error_filter(CAN_ERR_CRTL)
        .or_fail("set CAN_RAW_ERR_FILTER CRTL")?;
    only_err
        .set_error_filter(CAN_ERR_MASK)
        .or_fail("set CAN_RAW_ERR_FILTER all")?;
    only_err.set_filter_drop_all().or_fail("set zero filters")?;
    // A CAN_RAW_FILTER entry with CAN_ERR_FLAG in its mask is an error
    // filter on the classes left in the mask.
    let via_filter = canraw::open(idx)?;
    via_filter
        .set_filters(&[(0, CAN_ERR_FLAG | CAN_ERR_BUSOFF)])
        .or_fail("set filter (0, CAN_ERR_FLAG | BUSOFF)")?;

    let e1 = err_frame(CAN_ERR_BUSOFF, &[0, 0, 0, 0, 0, 0, 0, 0x11]);
    let e2 = err_frame(CAN_ERR_CRTL, &[0, 0x04, 0, 0, 0, 0, 0, 0x22]);
    let marker = std(0x42, &[0xEE]);
    for f in [&e1, &e2, &marker] {
        canraw::send(&tx, f)?;
    }
    canraw::expect_seq(&busoff, &[e1, marker], "socket with error mask BUSOFF")?;
    canraw::expect_seq(&crtl, &[e2, marker], "socket with error mask CRTL")?;
    canraw::expect_seq(&default, &[marker], "socket with error mask 0")?;
    canraw::expect_seq(
        &only_err,
        &[e1, e2],
        "socket with error mask CAN_ERR_MASK and zero filters",
    )?;
    canraw::expect_seq(
        &via_filter,
        &[e1],
        "socket with filter (0, CAN_ERR_FLAG | BUSOFF)",
    )?;
    expect_quiet(&[
        ("filter (0, CAN_ERR_FLAG | BUSOFF)", &via_filter),
        ("BUSOFF", &busoff),
        ("CRTL", &crtl),
        ("default", &default),
        ("errors only", &only_err),
    ])
}

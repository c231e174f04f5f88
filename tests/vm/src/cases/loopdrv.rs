// SPDX-License-Identifier: GPL-2.0
//! The rcan_loop driver: droprate, device count, statistics, verbose log.

use std::time::Duration;

use rcan_uapi::{ArbSocket, CAN_MASK_ANY};

use super::test_table;
use crate::check::{
    ensure, expect_frame, expect_frames, expect_none, is_subsequence, recv_frame, seq_frame,
    wait_for, Frame, TestResult,
};
use crate::ctx::{dev, Ctx, Module};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    loop_droprate_0,
    loop_droprate_100,
    loop_droprate_50,
    loop_droprate_invalid,
    loop_count_16,
    loop_statistics,
    loop_verbose_log,
];

/// Frames sent per batch before receiving them: small enough that neither
/// the socket's receive buffer nor any device queue can overflow.
const BATCH: usize = 50;

/// tx_packets + tx_dropped of `dev`.
fn tx_accounted(ctx: &Ctx, dev: &str) -> Result<u64, String> {
    Ok(ctx.stat(dev, "tx_packets")? + ctx.stat(dev, "tx_dropped")?)
}

/// Sends `seq_frame(0..n)` on can0 in batches. After each batch, waits until
/// the driver has accounted for every frame (reflected or dropped) and
/// receives the reflected ones. Returns what `rx` received.
fn transfer(
    ctx: &Ctx,
    tx: &ArbSocket,
    rx: &ArbSocket,
    idx: u32,
    n: usize,
) -> Result<Vec<Frame>, String> {
    let d = dev(0);
    let base_packets = ctx.stat(&d, "tx_packets")?;
    let base_all = tx_accounted(ctx, &d)?;
    let mut got = Vec::with_capacity(n);
    for start in (0..n).step_by(BATCH) {
        let end = (start + BATCH).min(n);
        for i in start..end {
            seq_frame(i).send(tx, idx)?;
        }
        let sent = end as u64;
        wait_for(
            Duration::from_secs(5),
            "tx_packets + tx_dropped to count every frame",
            || Ok((tx_accounted(ctx, &d)? - base_all >= sent).then_some(())),
        )?;
        let reflected = (ctx.stat(&d, "tx_packets")? - base_packets) as usize;
        while got.len() < reflected {
            let r = recv_frame(rx).map_err(|e| {
                format!("frame #{} of {reflected} reflected so far: {e}", got.len())
            })?;
            got.push(r.frame);
        }
    }
    expect_none(&[rx])?;
    Ok(got)
}

fn droprate_setup(ctx: &mut Ctx, rate: u32) -> Result<(u32, ArbSocket, ArbSocket), String> {
    ctx.load_stack(&[&format!("droprate={rate}")])?;
    let idx = ctx.ifindex(&dev(0))?;
    Ok((idx, ctx.socket()?, ctx.bound(0, CAN_MASK_ANY, idx)?))
}

/// droprate=0: 1000 frames, all received in order and intact.
fn loop_droprate_0(ctx: &mut Ctx) -> TestResult {
    let (idx, tx, rx) = droprate_setup(ctx, 0)?;
    let got = transfer(ctx, &tx, &rx, idx, 1000)?;
    ensure!(got.len() == 1000, "received {} of 1000 frames", got.len());
    if let Some(i) = (0..1000).find(|&i| got[i] != seq_frame(i)) {
        return Err(format!(
            "frame #{i}: expected {}, got {}",
            seq_frame(i),
            got[i]
        ));
    }
    let dropped = ctx.stat(&dev(0), "tx_dropped")?;
    ensure!(dropped == 0, "tx_dropped = {dropped} with droprate=0");
    Ok(())
}

/// droprate=100: nothing is reflected; tx_dropped counts every frame.
fn loop_droprate_100(ctx: &mut Ctx) -> TestResult {
    let (idx, tx, rx) = droprate_setup(ctx, 100)?;
    for i in 0..200 {
        seq_frame(i).send(&tx, idx)?;
    }
    let d = dev(0);
    wait_for(Duration::from_secs(5), "tx_dropped == 200", || {
        let n = ctx.stat(&d, "tx_dropped")?;
        ensure!(n <= 200, "tx_dropped = {n} after 200 frames");
        Ok((n == 200).then_some(()))
    })?;
    expect_none(&[&rx])?;
    for c in ["tx_packets", "rx_packets", "tx_bytes", "rx_bytes"] {
        let v = ctx.stat(&d, c)?;
        ensure!(v == 0, "{c} = {v} with droprate=100");
    }
    Ok(())
}

/// droprate=50: some but not all of 1000 frames arrive, in order.
fn loop_droprate_50(ctx: &mut Ctx) -> TestResult {
    let (idx, tx, rx) = droprate_setup(ctx, 50)?;
    let got = transfer(ctx, &tx, &rx, idx, 1000)?;
    let sent: Vec<Frame> = (0..1000).map(seq_frame).collect();
    let d = dev(0);
    let (packets, dropped) = (ctx.stat(&d, "tx_packets")?, ctx.stat(&d, "tx_dropped")?);
    ctx.note(format!(
        "droprate=50: received {} of 1000 frames (tx_packets {packets}, tx_dropped {dropped})",
        got.len()
    ));
    ensure!(
        !got.is_empty() && got.len() < 1000,
        "received {} of 1000 frames with droprate=50",
        got.len()
    );
    ensure!(
        packets + dropped == 1000 && packets == got.len() as u64,
        "tx_packets {packets} + tx_dropped {dropped} vs 1000 sent, {} received",
        got.len()
    );
    ensure!(
        is_subsequence(&got, &sent),
        "received frames are not the sent sequence with gaps (reordered or altered)"
    );
    Ok(())
}

/// droprate out of range: insmod fails and the module is not loaded.
fn loop_droprate_invalid(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    ensure!(
        ctx.insmod(Module::Loop, &["droprate=101"]).is_err(),
        "insmod rcan_loop droprate=101 succeeded"
    );
    ensure!(
        !ctx.is_loaded(Module::Loop),
        "rcan_loop is loaded after a failed insmod"
    );
    // A valid value still loads.
    ctx.insmod(Module::Loop, &["droprate=100"])?;
    ctx.rmmod(Module::Loop)
}

/// count=16: can0..can15 exist, and the last one works.
fn loop_count_16(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&["count=16"])?;
    ensure!(
        ctx.ifindex(&dev(16)).is_err(),
        "count=16 created a 17th device can16"
    );
    let idx = ctx.ifindex(&dev(15))?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let f = Frame::ext(0x15, &[15]);
    f.send(&rx, idx)?;
    expect_frame(&rx, &f, idx)
}

/// Counters after known traffic: packets and bytes (= DLC) on both sides,
/// and only on the interface that carried the frames.
fn loop_statistics(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&["count=2"])?;
    let (d0, d1) = (dev(0), dev(1));
    let i0 = ctx.ifindex(&d0)?;
    let i1 = ctx.ifindex(&d1)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, 0)?;
    let tx = ctx.socket()?;
    let frames = [
        Frame::std(0x1, &[1, 2]),
        Frame::ext(0x2, &[0; 8]),
        Frame::std(0x3, &[]),
        Frame::std(0x4, &[4; 5]),
    ];
    for f in &frames {
        f.send(&tx, i0)?;
    }
    expect_frames(&rx, &frames, i0)?;
    let counters = [
        "tx_packets",
        "rx_packets",
        "tx_bytes",
        "rx_bytes",
        "tx_dropped",
    ];
    expect_stats(ctx, &d0, &counters, [4, 4, 15, 15, 0])?;
    expect_stats(ctx, &d1, &counters, [0; 5])
        .map_err(|e| format!("without traffic on {d1}: {e}"))?;

    // A remote frame counts as a packet; its bytes are its DLC (4) per the
    // spec, but a remote frame carries no data, so 0 is accepted as well.
    let r = Frame::remote_std(0x5, 4);
    r.send(&tx, i1)?;
    expect_frame(&rx, &r, i1)?;
    expect_stats(ctx, &d1, &["tx_packets", "rx_packets"], [1, 1])
        .map_err(|e| format!("after one remote frame: {e}"))?;
    for c in ["tx_bytes", "rx_bytes"] {
        let v = ctx.stat(&d1, c)?;
        ensure!(
            v == 4 || v == 0,
            "{d1} {c} = {v} after one remote frame with DLC 4"
        );
        if v == 0 {
            ctx.note(format!(
                "{d1} {c}: remote frames count 0 bytes, not their DLC"
            ));
        }
    }
    expect_none(&[&rx])
}

/// Waits (up to 2 s: a driver may count a frame just after handing it on)
/// until the `counters` of `dev` equal `want`.
fn expect_stats<const N: usize>(
    ctx: &Ctx,
    dev: &str,
    counters: &[&str; N],
    want: [u64; N],
) -> TestResult {
    let mut last = [0; N];
    let r = wait_for(Duration::from_secs(2), "the counters", || {
        for (v, c) in last.iter_mut().zip(counters) {
            *v = ctx.stat(dev, c)?;
        }
        Ok((last == want).then_some(()))
    });
    r.map_err(|_| {
        let show = |v: &[u64; N]| {
            counters
                .iter()
                .zip(v)
                .map(|(c, v)| format!("{c} {v}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!("{dev}: {}; expected {}", show(&last), show(&want))
    })
}

/// verbose=1 logs each frame with the device name and the identifier.
fn loop_verbose_log(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    ctx.insmod(Module::Loop, &["verbose=1"])?;
    ctx.links_up()?;
    let idx = ctx.ifindex(&dev(0))?;
    let mut log = ctx.kmsg()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let frames = [
        (Frame::std(0x123, &[0xDE, 0xAD]), "123"),
        (Frame::ext(0x1ABC_DEF0, &[1]), "1ABCDEF0"),
        (Frame::remote_std(0x456, 2), "456"),
    ];
    for (f, _) in &frames {
        f.send(&rx, idx)?;
        expect_frame(&rx, f, idx)?;
    }
    let mut lines = Vec::new();
    for (f, id) in &frames {
        wait_for(
            Duration::from_secs(2),
            &format!("a kernel log line for {f}"),
            || {
                lines.extend(log.read_new()?);
                Ok(lines
                    .iter()
                    .any(|l| l.contains("can0") && has_token(l, id))
                    .then_some(()))
            },
        )
        .map_err(|e| format!("{e}; new log lines: {lines:?}"))?;
    }
    Ok(())
}

/// Whether `line` contains `token` as a whole word (case-insensitive).
fn has_token(line: &str, token: &str) -> bool {
    line.split(|c: char| !c.is_ascii_alphanumeric())
        .any(|w| w.eq_ignore_ascii_case(token))
}

#[cfg(test)]
mod tests {
    #[test]
    fn tokens() {
        let l = "rcan_loop can0: tx STD 123 [2] DE AD";
        assert!(super::has_token(l, "123"));
        assert!(super::has_token(l, "can0"));
        assert!(!super::has_token(l, "12"));
        assert!(super::has_token("can0: EXT 1abcdef0 [1] 01", "1ABCDEF0"));
    }
}

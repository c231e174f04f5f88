// SPDX-License-Identifier: GPL-2.0
//! Lifetimes: unregistering an interface under bound and blocked sockets,
//! repeated load/unload, unload under traffic, closing sockets while
//! frames are being delivered to them.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicUsize, Ordering};
use std::thread;
use std::time::Duration;

use rcan_uapi::{arb_std, ArbSocket, CAN_MASK_ANY, CAN_MASK_EXACT};

use super::{stack1, test_table};
use crate::check::{
    ensure, errno_name, errno_of, errno_text, expect_errno, expect_frame, expect_none, wait_blocked,
    wait_for, wait_until, Frame, OnDrop, OrFail, TestResult, RECV_SYSCALLS, SETTLE,
};
use crate::sys::gettid;
use crate::ctx::{dev, sized, Ctx, Module};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    rmmod_loop_with_bound_sockets,
    reload_stack_repeated,
    rmmod_loop_under_traffic,
    close_sockets_during_traffic,
];

/// Brings rcan_loop back after it was removed and checks a round trip.
fn reload_loop(ctx: &mut Ctx, params: &[&str]) -> TestResult {
    ctx.insmod(Module::Loop, params)?;
    ctx.links_up()?;
    let idx = ctx.ifindex(&dev(0))?;
    let s = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let f = Frame::std(0x600, &[6, 0, 0]);
    f.send(&s, idx)?;
    expect_frame(&s, &f, idx).map_err(|e| format!("after reloading rcan_loop: {e}"))
}

/// rmmod rcan_loop with one socket bound to can0 and another blocked in
/// recv on it: rmmod succeeds, the blocked recv and the next recv of the
/// idle socket return ENODEV (once), sendto the old ifindex is ENODEV.
fn rmmod_loop_with_bound_sockets(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let idle = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let blocked = ctx.bound(0, CAN_MASK_ANY, idx)?;
    blocked
        .set_rcvtimeo(SETTLE)
        .or_fail("SO_RCVTIMEO")?;

    let tid = AtomicI32::new(0);
    thread::scope(|sc| -> TestResult {
        let h = sc.spawn(|| {
            tid.store(gettid(), Ordering::SeqCst);
            blocked.recv_from(&mut [0u8; 8])
        });
        // The receiver is blocked in recvfrom before the interface goes.
        wait_blocked(&tid, &RECV_SYSCALLS, "the receiver blocked in recvfrom")?;
        let rm = ctx.rmmod(Module::Loop);
        let r = h
            .join()
            .map_err(|_| "receiver thread panicked".to_string())?;
        rm?;
        expect_errno(
            r,
            libc::ENODEV,
            "recv blocked while the interface went away",
        )
    })?;

    let mut buf = [0u8; 8];
    expect_errno(
        idle.recv_from_flags(&mut buf, libc::MSG_DONTWAIT),
        libc::ENODEV,
        "first recv after the interface went away",
    )?;
    expect_errno(
        idle.recv_from_flags(&mut buf, libc::MSG_DONTWAIT),
        libc::EAGAIN,
        "second recv after the interface went away (ENODEV is reported once)",
    )?;
    let f = Frame::std(0x1, &[1]);
    expect_errno(
        idle.send_to(&f.data, f.arb, idx),
        libc::ENODEV,
        "sendto the old ifindex",
    )?;
    let fresh = ctx.socket()?;
    expect_errno(
        fresh.send_to(&f.data, f.arb, idx),
        libc::ENODEV,
        "sendto the old ifindex (new socket)",
    )?;
    drop((idle, blocked, fresh));
    reload_loop(ctx, &[])
}

/// Load and unload the whole stack 20 times (`RCAN_RELOAD_ROUNDS`; 6 on the
/// debug kernel, where a round takes ~10 s and 20 of them overran the
/// runner's watchdog in CI), with a round trip each time.
fn reload_stack_repeated(ctx: &mut Ctx) -> TestResult {
    for round in 0..sized("RCAN_RELOAD_ROUNDS", 20, 6) {
        let step = |ctx: &mut Ctx| -> TestResult {
            ctx.load_stack(&["count=2"])?;
            let idx = ctx.ifindex(&dev(round as usize % 2))?;
            let s = ctx.bound(0, CAN_MASK_ANY, idx)?;
            let f = Frame::ext(round, &[round as u8; 3]);
            f.send(&s, idx)?;
            expect_frame(&s, &f, idx)?;
            drop(s);
            ctx.unload_all()?;
            for m in Module::ALL {
                ensure!(!ctx.is_loaded(m), "{} still loaded", m.name());
            }
            Ok(())
        };
        step(ctx).map_err(|e| format!("round {round}: {e}"))?;
    }
    Ok(())
}

/// Counts of results per errno (0 = success).
type Tally = BTreeMap<i32, usize>;

fn tally_text(t: &Tally) -> String {
    t.iter()
        .map(|(e, n)| match e {
            0 => format!("ok {n}"),
            e => format!("{} {n}", errno_name(*e)),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// rmmod rcan_loop while one thread sends on can0 as fast as it can and
/// another receives; five rounds. Send errors after the removal are
/// expected; nothing may hang, and the driver must load again afterwards.
fn rmmod_loop_under_traffic(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&[])?;
    for round in 0..5 {
        let idx = ctx.ifindex(&dev(0))?;
        let tx = ctx.socket()?;
        let rx = ctx.bound(0, CAN_MASK_ANY, 0)?;
        rx.set_rcvtimeo(Duration::from_millis(100))
            .or_fail("SO_RCVTIMEO")?;
        let stop = AtomicBool::new(false);
        let sent_ok = AtomicUsize::new(0);
        let sent_err = AtomicUsize::new(0);
        let recv_ok = AtomicUsize::new(0);
        let (sent, received) = thread::scope(|sc| -> Result<(Tally, Tally), String> {
            let _stop = OnDrop(|| stop.store(true, Ordering::SeqCst));
            let sender = sc.spawn(|| {
                let mut t = Tally::new();
                let mut i = 0u32;
                while !stop.load(Ordering::SeqCst) {
                    let r = tx.send_to(&i.to_le_bytes(), arb_std(i & 0x7FF, false), idx);
                    if r.is_ok() {
                        sent_ok.fetch_add(1, Ordering::SeqCst);
                    } else {
                        sent_err.fetch_add(1, Ordering::SeqCst);
                    }
                    *t.entry(r.err().map_or(0, |e| errno_of(&e))).or_default() += 1;
                    i = i.wrapping_add(1);
                }
                t
            });
            let receiver = sc.spawn(|| {
                let mut t = Tally::new();
                while !stop.load(Ordering::SeqCst) {
                    let r = rx.recv(&mut [0u8; 8], 0);
                    if r.is_ok() {
                        recv_ok.fetch_add(1, Ordering::SeqCst);
                    }
                    *t.entry(r.err().map_or(0, |e| errno_of(&e))).or_default() += 1;
                }
                t
            });
            // Traffic first (on a loaded debug kernel a new thread may take
            // longer than any fixed sleep to send its first frame).
            // Then until both ends have moved on by more: the rmmod hits
            // traffic that is flowing.
            let (s0, r0) = wait_for(SETTLE, "the first frame sent and received", || {
                let c = (sent_ok.load(Ordering::SeqCst), recv_ok.load(Ordering::SeqCst));
                Ok((c.0 > 0 && c.1 > 0).then_some(c))
            })?;
            wait_until(SETTLE, "traffic going on", || {
                sent_ok.load(Ordering::SeqCst) > s0 + 16 && recv_ok.load(Ordering::SeqCst) > r0 + 16
            })?;
            let rm = ctx.rmmod(Module::Loop);
            // The sender has tried the vanished interface.
            let e0 = sent_err.load(Ordering::SeqCst);
            if rm.is_ok() {
                wait_until(SETTLE, "a send failing after the rmmod", || {
                    sent_err.load(Ordering::SeqCst) > e0
                })?;
            }
            stop.store(true, Ordering::SeqCst);
            let sent = sender.join().map_err(|_| "sender panicked".to_string())?;
            let received = receiver
                .join()
                .map_err(|_| "receiver panicked".to_string())?;
            rm.map_err(|e| format!("round {round}: rmmod under traffic: {e}"))?;
            Ok((sent, received))
        })?;
        ctx.note(format!(
            "round {round}: sendto [{}], recv [{}]",
            tally_text(&sent),
            tally_text(&received)
        ));
        ensure!(
            sent.get(&0).copied().unwrap_or(0) > 0,
            "round {round}: no frame was sent before rmmod"
        );
        drop((tx, rx));
        reload_loop(ctx, &[]).map_err(|e| format!("round {round}: {e}"))?;
    }
    Ok(())
}

/// A receiver collects 1000 frames (100 ms receive timeout, looping) while
/// a churn thread keeps opening, binding and closing sockets with the same
/// filter, so deliveries race with socket release. Every frame must reach
/// the receiver exactly once, in order.
fn close_sockets_during_traffic(ctx: &mut Ctx) -> TestResult {
    const N: usize = 1000;
    const BATCH: usize = 50;
    let idx = stack1(ctx)?;
    let arb = arb_std(0x321, false);
    let rx = ctx.bound(arb, CAN_MASK_EXACT, idx)?;
    rx.set_rcvtimeo(Duration::from_millis(100))
        .or_fail("SO_RCVTIMEO")?;
    let tx = ctx.socket()?;
    let done = AtomicBool::new(false);
    let count = AtomicUsize::new(0);
    let frame = |i: usize| {
        let mut d = [0u8; 8];
        d[..4].copy_from_slice(&(i as u32).to_le_bytes());
        d[4..].copy_from_slice(&(!(i as u32)).to_le_bytes());
        Frame::with_arb(arb, &d)
    };

    let (got, churned) = thread::scope(|sc| -> Result<(Vec<Frame>, usize), String> {
        let _done = OnDrop(|| done.store(true, Ordering::SeqCst));
        let receiver = sc.spawn(|| -> Result<Vec<Frame>, String> {
            let mut got = Vec::with_capacity(N);
            loop {
                let mut buf = [0u8; 8];
                match rx.recv_from(&mut buf) {
                    Ok((n, a)) => {
                        got.push(Frame::with_arb(a.arb, &buf[..n]));
                        count.fetch_add(1, Ordering::SeqCst);
                    }
                    Err(e) if errno_of(&e) == libc::EAGAIN => {
                        if done.load(Ordering::SeqCst) {
                            return Ok(got);
                        }
                    }
                    Err(e) => return Err(format!("receiver: {}", errno_text(&e))),
                }
            }
        });
        let churn = sc.spawn(|| -> Result<usize, String> {
            let mut n = 0usize;
            while !done.load(Ordering::SeqCst) {
                let s = ArbSocket::new().or_fail("churn socket")?;
                s.bind(
                    arb,
                    CAN_MASK_EXACT,
                    if n.is_multiple_of(2) { idx } else { 0 },
                )
                .or_fail("churn bind")?;
                if n.is_multiple_of(3) {
                    let _ = s.recv(&mut [0u8; 8], libc::MSG_DONTWAIT);
                }
                drop(s);
                n += 1;
            }
            Ok(n)
        });

        let mut result = Ok(());
        for start in (0..N).step_by(BATCH) {
            let end = (start + BATCH).min(N);
            let step = (start..end)
                .try_for_each(|i| frame(i).send(&tx, idx))
                .and_then(|()| {
                    wait_for(Duration::from_secs(5), "the receiver to catch up", || {
                        Ok((count.load(Ordering::SeqCst) >= end).then_some(()))
                    })
                });
            if let Err(e) = step {
                result = Err(format!(
                    "after {} frames received: {e}",
                    count.load(Ordering::SeqCst)
                ));
                break;
            }
        }
        done.store(true, Ordering::SeqCst);
        let got = receiver
            .join()
            .map_err(|_| "receiver panicked".to_string())?;
        let churned = churn
            .join()
            .map_err(|_| "churn thread panicked".to_string())?;
        result?;
        Ok((got?, churned?))
    })?;

    ctx.note(format!(
        "{churned} sockets opened and closed during the transfer"
    ));
    ensure!(got.len() == N, "received {} of {N} frames", got.len());
    if let Some(i) = (0..N).find(|&i| got[i] != frame(i)) {
        return Err(format!("frame #{i}: expected {}, got {}", frame(i), got[i]));
    }
    expect_none(&[&rx])
}

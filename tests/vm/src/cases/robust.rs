// SPDX-License-Identifier: GPL-2.0
//! Robustness checks of issue 15 that are neither a teardown race nor an
//! info leak of one call (robustness.rst):
//!
//! * `dsor_loss_accounting`: DSOR over canloop dropping 30 % and 50 % of
//!   all frames, messages of random lengths, every message accounted for:
//!   intact, corrupted (must be 0), duplicated (must be 0), lost and
//!   reported to the sender (ETIMEDOUT), lost silently (must be 0), and
//!   reported but delivered (the acks of the last frame lost: dsor.rst,
//!   "Delivery reports"). Each message is received into a buffer filled
//!   with 0xAA: only the message's bytes may change (DSOR message bodies
//!   are built from reassembly buffers, which see retransmissions).
//! * `modules_load_unload_cycles`: every module loaded and unloaded many
//!   times in a row (those that find no hardware here: their failing
//!   probe, as many times), then a kmemleak scan on the debug kernel must
//!   show no new unreferenced object.

use std::collections::HashMap;
use std::fs;
use std::time::{Duration, Instant};

use rcan_uapi::dsor::{DsorAddr, DsorSocket, DSOR_ID_ANY};

use super::test_table;
use crate::check::{ensure, errno_of, wait_until, OrFail, TestResult, SETTLE};
use crate::ctx::{sized, Ctx, Module};
use crate::sys::FILL;
use crate::Test;

pub const OURS: &[Test] = test_table![dsor_loss_accounting, modules_load_unload_cycles];

/// SplitMix64: a seeded, reproducible stream of message lengths.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// The content of message `id` of `len` bytes: no two messages of a
/// round alike, so a mix-up shows as corruption.
fn body(id: u32, len: usize) -> Vec<u8> {
    (0..len as u32)
        .map(|i| (i.wrapping_mul(131) ^ id.wrapping_mul(0x9E37_79B9).rotate_left(i % 32)) as u8)
        .collect()
}

fn set_droprate(rate: u32) -> TestResult {
    fs::write(
        "/sys/module/rcan_loop/parameters/droprate",
        format!("{rate}\n"),
    )
    .or_fail("write droprate")
}

/// What became of the messages of one round.
#[derive(Default, Debug)]
struct Account {
    intact: usize,
    corrupted: usize,
    duplicated: usize,
    lost_reported: usize,
    reported_delivered: usize,
    lost_silently: usize,
}

/// Receives whatever `rx` has within its timeout into 0xAA-filled buffers:
/// checks that nothing past the returned length changed, and counts each
/// copy of each message (`copies`) and each copy that is not the message
/// sent (`bad`).
fn drain(
    rx: &DsorSocket,
    lens: &HashMap<u32, usize>,
    copies: &mut HashMap<u32, usize>,
    bad: &mut Vec<String>,
    buf_len: usize,
) -> TestResult {
    loop {
        let mut buf = vec![FILL; buf_len];
        match rx.recv_from(&mut buf) {
            Ok((n, Some(DsorAddr::Segm { id, .. }))) => {
                ensure!(
                    buf[n.min(buf_len)..].iter().all(|&b| b == FILL),
                    "message {id:#x}: buffer written past the {n} bytes returned"
                );
                *copies.entry(id).or_default() += 1;
                match lens.get(&id) {
                    Some(&len) if n == len && buf[..n] == body(id, len) => {}
                    Some(&len) => bad.push(format!("{id:#x}: {n} bytes, sent {len}")),
                    None => bad.push(format!("{id:#x}: never sent")),
                }
            }
            Ok((_, a)) => return Err(format!("a message from {a:?}")),
            Err(e) if errno_of(&e) == libc::EAGAIN => return Ok(()),
            Err(e) => return Err(format!("recvfrom: {e}")),
        }
    }
}

/// DSOR at 30 % and 50 % frame loss (canloop `droprate`), messages of
/// random length (0 to 160 and 0 to 80 bytes; seed `RCAN_LOSS_SEED`,
/// default 1), 40 per rate (5 on the debug kernel, where 12 took 308 s
/// on a loaded host;
/// `RCAN_LOSS_MESSAGES`), each sent blocking (success = the receiver
/// acknowledged the last frame after queueing the message).
fn dsor_loss_accounting(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&[])?;
    // Short timers keep it short; the protocol is the same.
    ctx.insmod(
        Module::Dsor,
        &["ifname=can0", "ack_timeout_ms=20", "reasm_timeout_ms=1000"],
    )?;
    let seed = std::env::var("RCAN_LOSS_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1u64);
    let count = sized("RCAN_LOSS_MESSAGES", 40, 5);
    let mut rng = Rng(seed);
    let rx = DsorSocket::new().or_fail("DSOR socket")?;
    rx.bind(&DsorAddr::Segm {
        prio: 0,
        node: 0,
        id: DSOR_ID_ANY,
    })
    .or_fail("bind")?;
    rx.set_rcvtimeo(Duration::from_millis(100))
        .or_fail("SO_RCVTIMEO")?;
    let tx = DsorSocket::new().or_fail("DSOR socket")?;
    let res = (|| -> TestResult {
        for (rate, max_len) in [(30u32, 160usize), (50, 80)] {
            set_droprate(rate)?;
            let mut lens = HashMap::new();
            let mut reported = Vec::new();
            let mut copies = HashMap::new();
            let mut bad = Vec::new();
            for j in 0..count {
                let id = rate << 16 | j;
                let len = rng.below(max_len + 1);
                lens.insert(id, len);
                let a = DsorAddr::Segm {
                    prio: 0x30,
                    node: 0,
                    id,
                };
                match tx.send_to(&body(id, len), &a) {
                    Ok(n) => ensure!(n == len, "message {j}: sent {n} of {len}"),
                    Err(e) if errno_of(&e) == libc::ETIMEDOUT => reported.push(id),
                    Err(e) => {
                        return Err(format!("droprate {rate}: message {j} ({len} bytes): {e}"))
                    }
                }
                drain(&rx, &lens, &mut copies, &mut bad, max_len + 64)?;
            }
            // Every send has returned, so no retransmission is still to
            // come; frames of them may still be on their way. A marker
            // message sent now without loss queues behind them: once its
            // send has returned (acknowledged: delivered), collect the
            // rest (was 500 ms): a message whose last frame arrived while
            // every ack of it was lost is there too.
            set_droprate(0)?;
            let marker = rate << 16 | 0xffff;
            lens.insert(marker, 8);
            tx.send_to(
                &body(marker, 8),
                &DsorAddr::Segm {
                    prio: 0x30,
                    node: 0,
                    id: marker,
                },
            )
            .map_err(|e| format!("droprate {rate}: the marker message: {e}"))?;
            drain(&rx, &lens, &mut copies, &mut bad, max_len + 64)?;
            lens.remove(&marker);
            ensure!(
                copies.remove(&marker) == Some(1),
                "droprate {rate}: the marker message was not delivered once"
            );
            let mut acc = Account {
                corrupted: bad.len(),
                ..Default::default()
            };
            for (&id, _) in lens.iter() {
                let c = copies.get(&id).copied().unwrap_or(0);
                let was_reported = reported.contains(&id);
                match (c, was_reported) {
                    (0, true) => acc.lost_reported += 1,
                    (0, false) => acc.lost_silently += 1,
                    (1, true) => acc.reported_delivered += 1,
                    (1, false) => acc.intact += 1,
                    _ => acc.duplicated += 1,
                }
            }
            let text = format!(
                "droprate {rate}%: {count} messages of 0..={max_len} bytes (seed {seed}): {} intact, \
                 {} corrupted, {} duplicated, {} lost and reported (ETIMEDOUT), {} reported but \
                 delivered, {} lost silently",
                acc.intact,
                acc.corrupted,
                acc.duplicated,
                acc.lost_reported,
                acc.reported_delivered,
                acc.lost_silently
            );
            ctx.note(&text);
            ensure!(
                acc.corrupted == 0 && acc.duplicated == 0 && acc.lost_silently == 0,
                "{text}; corrupted: {bad:?}"
            );
            ensure!(acc.intact > 0, "{text}: nothing got through");
        }
        Ok(())
    })();
    let reset = set_droprate(0);
    res.and(reset)
}

fn rmmod_retrying(ctx: &mut Ctx, m: Module) -> TestResult {
    let mut last = String::new();
    wait_until(SETTLE, &format!("rmmod {} to succeed", m.name()), || match ctx.rmmod(m) {
        Ok(()) => true,
        Err(e) => {
            last = e;
            false
        }
    })
    .map_err(|e| format!("{e}: {last}"))
}

/// Every module (`Module::ALL`) loaded and unloaded `RCAN_MODULE_CYCLES`
/// times in a row (100 on the release kernel; 1 on the debug kernel,
/// where one cycle of every module takes some 25 s), the watchdog
/// restarted after each module, with the modules it needs loaded around
/// it; the three whose hardware QEMU does not have (ISA SJA1000, TS-CAN1,
/// ISA 82527) fail their probe as many times (EINVAL or ENODEV) and must
/// not stay listed.
///
/// What repeated init/exit catches is state that one load leaves for the
/// next: a registration not undone (the next `register_netdev`,
/// `pci_register_driver`, `sock_register` or `rtnl_link_register` fails
/// with EEXIST/EBUSY), a reference not dropped (the next rmmod fails with
/// EBUSY and `rmmod_retrying` gives up after a minute), an id or name
/// leaked per load (canN or an IDA; 100 loads of `rcan_loop count=2`
/// cover 200 interfaces), a timer or work item left armed (it fires into
/// freed module text within its period), and memory: the suite's VMs
/// boot with kmemleak on (the release kernel has it built in, off unless
/// `kmemleak=on`; `vm-run.sh --kmemleak`), and the scan that ends every
/// run (tools/testing/rcan/vm/init; any report fails the stage) sees a
/// per-load leak a hundred times over on release. (From 2026-11-27 to
/// 2026-12-01 this ran 20 cycles, to save 190 s of the release stage,
/// and kmemleak over 100 cycles had been run once by hand; issue 40 asked
/// for both back.)
fn modules_load_unload_cycles(ctx: &mut Ctx) -> TestResult {
    let n = sized("RCAN_MODULE_CYCLES", 100, 1);
    // (module, parameters, modules it needs, loads: false if it must fail)
    let stack = [Module::Pf, Module::Can, Module::Raw, Module::Loop];
    let plan: [(Module, &[&str], &[Module], bool); 21] = [
        (Module::Pf, &[], &[], true),
        (Module::Can, &[], &[Module::Pf], true),
        (Module::Raw, &[], &[Module::Pf], true),
        (Module::Bcm, &[], &[Module::Pf], true),
        (Module::Isotp, &[], &[Module::Pf], true),
        (Module::J1939, &[], &[Module::Pf], true),
        (Module::Loop, &["count=2"], &[Module::Pf], true),
        (Module::Dsor, &["ifname=can0"], &stack, true),
        (Module::Time, &[], &stack, true),
        (Module::Rtime, &[], &stack, true),
        (Module::Dev, &[], &[Module::Pf], true),
        (
            Module::Kvaser,
            &super::sja1000::PRESET_500K,
            &[Module::Pf, Module::Dev],
            true,
        ),
        (
            Module::Advantech,
            &super::sja1000::PRESET_500K,
            &[Module::Pf, Module::Dev],
            true,
        ),
        (Module::Pcan, &[], &[Module::Pf, Module::Dev], true),
        (
            Module::Isa,
            &["iomem=0xd0000", "irq=5"],
            &[Module::Pf, Module::Dev],
            false,
        ),
        (Module::Tscan1, &[], &[Module::Pf, Module::Dev], false),
        (Module::I82527Sim, &["cards=2"], &[Module::Pf], true),
        (
            Module::Sja1000Sim,
            &["cards=2"],
            &[Module::Pf, Module::Dev],
            true,
        ),
        (
            Module::I82527Isa,
            &["iomem=0xd0000", "irq=5"],
            &[Module::Pf],
            false,
        ),
        (Module::CtuCanFdPci, &[], &[Module::Pf, Module::Dev], true),
        (
            Module::CtuCanFdSim,
            &["cards=2"],
            &[Module::Pf, Module::Dev],
            true,
        ),
    ];
    // A module added to Module::ALL without a line here would go
    // untested: fail instead.
    for m in Module::ALL {
        ensure!(
            plan.iter().any(|p| p.0 == m),
            "{} is in Module::ALL but not in this test's plan",
            m.name()
        );
    }
    let mut total = 0.0;
    for (m, params, deps, loads) in plan {
        ctx.unload_all()?;
        for &d in deps {
            let p: &[&str] = if d == Module::Loop { &["count=2"] } else { &[] };
            ctx.insmod(d, p)?;
        }
        if deps.contains(&Module::Loop) {
            ctx.links_up()?;
        }
        let t0 = Instant::now();
        for i in 0..n {
            let r = ctx.insmod(m, params);
            match (r, loads) {
                (Ok(()), true) => {
                    rmmod_retrying(ctx, m).map_err(|e| format!("{} cycle {i}: {e}", m.name()))?
                }
                (Err(e), true) => return Err(format!("{} cycle {i}: {e}", m.name())),
                (Ok(()), false) => {
                    return Err(format!(
                        "{} cycle {i}: loaded without its hardware",
                        m.name()
                    ))
                }
                (Err(e), false) => ensure!(
                    (e.contains("No such device") || e.contains("Invalid argument"))
                        && !ctx.is_loaded(m),
                    "{} cycle {i}: {e}, expected ENODEV or EINVAL and not listed",
                    m.name()
                ),
            }
        }
        let took = t0.elapsed().as_secs_f64();
        ctx.note(format!("{}: {n} cycles in {took:.1} s", m.name()));
        // The watchdog bounds each module's cycles, not all of them.
        crate::heartbeat();
        total += took;
    }
    ctx.unload_all()?;
    ctx.note(format!(
        "{n} cycles of {} modules in {total:.1} s",
        plan.len()
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bodies_differ() {
        assert_eq!(body(7, 0), Vec::<u8>::new());
        assert_ne!(body(1, 64), body(2, 64));
        assert_eq!(body(1, 64)[..10], body(1, 10)[..]);
        let mut r = Rng(1);
        let v: Vec<usize> = (0..100).map(|_| r.below(161)).collect();
        assert!(v.iter().any(|&l| l == 0 || l < 8) && v.iter().any(|&l| l > 120));
    }
}

// SPDX-License-Identifier: GPL-2.0
//! A CAN gateway in user space, as users write one where `cangw` is not
//! available: a CAN_RAW socket on can0 that forwards every frame it
//! receives to can1, at the full rate a sender can burst, with every frame
//! checked on can1 and the interfaces' drop counters checked afterwards.

use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanFrame, CanSocket, Frame, Socket};

use super::{portable_table, raw2};
use crate::canraw::{self, ext, show, std as sff};
use crate::check::{ensure, errno_text, OrFail, TestResult};
use crate::ctx::{dev, sized, Ctx};
use crate::sys;
use crate::Test;

pub const TESTS: &[Test] = portable_table![raw_gateway_burst];

/// Frames in [`raw_gateway_burst`] (`RCAN_GW_BURST`; default 2,000, or 300
/// on the debug kernel, where each frame costs some hundred times more).
fn burst_len() -> u32 {
    sized("RCAN_GW_BURST", 2_000, 300)
}

/// The `seq`-th frame of the burst: standard and extended frames in turn,
/// DLC 0..8, the sequence number in the identifier and the data, so a
/// frame out of place, lost, doubled or altered is recognised.
fn burst_frame(seq: u32) -> CanFrame {
    let dlc = (seq % 9) as usize;
    let mut d = [0u8; 8];
    d[..4].copy_from_slice(&seq.to_le_bytes());
    d[4..].copy_from_slice(&(!seq).to_le_bytes());
    if seq.is_multiple_of(2) {
        sff((seq % 0x800) as u16, &d[..dlc])
    } else {
        ext(0x1000_0000 | seq, &d[..dlc])
    }
}

/// How long a sender keeps retrying one frame that fails with ENOBUFS
/// before giving up (a bound against hanging, not a timing check).
const ENOBUFS_LIMIT: Duration = Duration::from_secs(10);

/// Writes `f`, as mainline CAN applications do: a blocking socket can
/// still fail with ENOBUFS when the interface's transmit queue is full
/// (the queueing discipline drops the frame; nothing blocks for a queue).
/// Then poll for POLLOUT and retry. Returns the number of retries.
fn send_retrying(s: &CanSocket, f: &CanFrame) -> Result<u64, String> {
    let mut retries = 0;
    let start = Instant::now();
    loop {
        match s.write_frame(f) {
            Ok(()) => return Ok(retries),
            Err(e) if e.raw_os_error() == Some(libc::ENOBUFS) => {
                ensure!(
                    start.elapsed() < ENOBUFS_LIMIT,
                    "write {}: ENOBUFS for {ENOBUFS_LIMIT:?} ({retries} retries)",
                    show(f)
                );
                retries += 1;
                sys::poll_one(s, libc::POLLOUT, 10).or_fail("poll POLLOUT")?;
                // The socket is writable as soon as its send buffer has
                // room, which says nothing about the device queue: give it
                // a moment before the next try (a back-off, bounded by
                // ENOBUFS_LIMIT, not synchronisation).
                thread::sleep(Duration::from_millis(1));
            }
            Err(e) => return Err(format!("write {}: {}", show(f), errno_text(&e))),
        }
    }
}

/// Counters that grow when an interface, or the receive backlog in front
/// of the stack (netif_rx), drops a frame.
const DROP_COUNTERS: [&str; 4] = ["rx_dropped", "tx_dropped", "rx_errors", "tx_errors"];

/// The drop counters (and packet counts, for the notes) of can0 and can1.
fn counters(ctx: &Ctx) -> Result<Vec<(String, u64)>, String> {
    let mut v = Vec::new();
    for i in 0..2 {
        for c in DROP_COUNTERS.iter().chain(&["rx_packets", "tx_packets"]) {
            v.push((format!("{}/{c}", dev(i)), ctx.stat(&dev(i), c)?));
        }
    }
    Ok(v)
}

/// A gateway forwards a full-rate burst from can0 to can1 without loss:
/// a sender writes N numbered frames on can0 as fast as its blocking
/// socket lets it; the gateway, a CAN_RAW socket bound to can0, writes
/// every frame it reads to can1 through a CAN_RAW socket bound there; a
/// receiver on can1 gets all N, in order, intact, and nothing else. The
/// interfaces count no drop (rx/tx dropped and errors, which include
/// netif_rx backlog drops) and the kernel logs no dead-loop drop. The
/// gateway's and the receiver's sockets get a
/// receive buffer for the whole burst: nothing paces a sender on a
/// loopback device, so a smaller buffer could overflow in a slow VM,
/// which would be the test's fault, not the stack's. ENOBUFS on a write is
/// retried after poll (see [`send_retrying`]) and reported in a note.
fn raw_gateway_burst(ctx: &mut Ctx) -> TestResult {
    let n = burst_len();
    let (i0, i1) = raw2(ctx)?;
    let big = |s: &CanSocket| sys::set_rcvbufforce(s, 64 << 20).or_fail("SO_RCVBUFFORCE");
    let gw_in = canraw::open(i0)?;
    big(&gw_in)?;
    let gw_out = canraw::open(i1)?;
    let rx = canraw::open(i1)?;
    big(&rx)?;
    let tx = canraw::open(i0)?;
    let before = counters(ctx)?;
    let mut kmsg = ctx.kmsg()?;

    let gateway = thread::spawn(move || -> Result<u64, String> {
        let mut retries = 0;
        for i in 0..n {
            let f = canraw::recv(&gw_in).map_err(|e| format!("gateway, frame {i}: {e}"))?;
            retries += send_retrying(&gw_out, &f)?;
        }
        canraw::expect_quiet(&[("gateway socket on can0", &gw_in)])?;
        Ok(retries)
    });
    let receiver = thread::spawn(move || -> TestResult {
        for seq in 0..n {
            let want = burst_frame(seq);
            let got = canraw::recv(&rx)
                .map_err(|e| format!("can1: waiting for frame {seq} ({}): {e}", show(&want)))?;
            ensure!(
                canraw::same(&got, &want),
                "can1: frame {seq}: expected {}, got {} (id {:#x})",
                show(&want),
                show(&got),
                got.raw_id()
            );
        }
        canraw::expect_quiet(&[("receiver on can1", &rx)])
    });
    let start = Instant::now();
    let mut tx_retries = 0;
    for seq in 0..n {
        tx_retries += send_retrying(&tx, &burst_frame(seq))?;
    }
    let sent_secs = start.elapsed().as_secs_f64();
    let gw_retries = gateway
        .join()
        .map_err(|_| "gateway thread panicked".to_string())??;
    receiver
        .join()
        .map_err(|_| "receiver thread panicked".to_string())??;
    let secs = start.elapsed().as_secs_f64();

    // The core's messages when it drops a frame on a device without a
    // queue (canloop, vcan): a transmit re-entered from the device's own
    // transmit ("Dead loop on virtual device ...") or refused by it
    // ("Virtual device ... asks to queue packet!"). Both also count
    // tx_dropped.
    let dead: Vec<String> = kmsg
        .read_new()?
        .into_iter()
        .filter(|l| l.contains("Dead loop on virtual device") || l.contains("asks to queue packet"))
        .collect();
    ensure!(dead.is_empty(), "kernel log: {dead:?}");
    let after = counters(ctx)?;
    let mut deltas = Vec::new();
    for ((name, b), (_, a)) in before.iter().zip(&after) {
        deltas.push(format!("{name} +{}", a - b));
        if DROP_COUNTERS
            .iter()
            .any(|c| name.ends_with(&format!("/{c}")))
        {
            ensure!(a == b, "{name} grew by {} during the burst", a - b);
        }
    }
    ctx.note(format!(
        "gateway: {n} frames can0 -> can1, sent in {sent_secs:.1} s, all through in \
         {secs:.1} s ({:.0} frames/s); ENOBUFS retries: sender {tx_retries}, gateway \
         {gw_retries}; {}",
        f64::from(n) / secs,
        deltas.join(", ")
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use socketcan::EmbeddedFrame;

    #[test]
    fn burst_frames_are_distinct() {
        let a = burst_frame(0);
        assert_eq!(a.dlc(), 0);
        let b = burst_frame(9);
        assert_eq!(b.dlc(), 0);
        assert!(!canraw::same(&a, &b));
        let f = burst_frame(17);
        assert_eq!(f.dlc(), 8);
        assert_eq!(f.raw_id(), 0x1000_0011);
        assert_eq!(&f.data()[..4], &17u32.to_le_bytes());
        assert!(!canraw::same(&burst_frame(2048), &burst_frame(0)));
    }
}

// SPDX-License-Identifier: GPL-2.0
//! canzlogd's user-space work per frame, on the host (no CAN needed):
//! formatting a `candump -l` line and compressing it into a gzip member
//! per flush interval, as the daemon does, for N frames of random
//! identifiers, lengths and data (cangen's default mix: the worst case for
//! compression) at RATE frames per second of simulated bus time.
//!
//!     cargo run --release -p rcan-daemons --example zlog_cost [N] [RATE] [FLUSH_MS] [LEVEL]
//!
//! Prints CPU time (user + system, getrusage: not wall time, which a
//! loaded machine inflates) per frame and per 1,000 frames/s, and bytes per frame.
//! The system calls (poll, recvmsg, write, fdatasync) are not in it: see
//! tools/testing/rcan/daemons-measure.sh for the whole daemon in the VM.

use std::time::Duration;

use nix::sys::resource::{getrusage, UsageWho};

use rcan_daemons::frame::{candump_line, Frame};
use rcan_daemons::zlog::{Config, ZLog};

/// User + system CPU seconds of this process so far.
fn cpu_time() -> f64 {
    let u = getrusage(UsageWho::RUSAGE_SELF).expect("getrusage");
    let s = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
    s(u.user_time()) + s(u.system_time())
}

fn main() {
    let mut a = std::env::args()
        .skip(1)
        .map(|s| s.parse::<u64>().expect("a number"));
    let n = a.next().unwrap_or(1_000_000);
    let rate = a.next().unwrap_or(1000);
    let flush_ms = a.next().unwrap_or(1000);
    let level = a.next().unwrap_or(1) as u32;
    let dir = std::env::temp_dir().join(format!("zlog-cost-{}", std::process::id()));
    let mut z = ZLog::new(Config {
        dir: dir.clone(),
        prefix: "cost".into(),
        max_size: u64::MAX,
        max_age: Duration::from_secs(1 << 30),
        fsync: false,
        level,
    })
    .expect("temp dir");
    let per_flush = (rate * flush_ms / 1000).max(1);
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    let t0 = cpu_time();
    for i in 0..n {
        // xorshift: cheap, reproducible random frames.
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let len = (x % 9) as u8;
        let f = Frame {
            id: ((x >> 8) & 0x7FF) as u32,
            len,
            data: (x >> 3).to_le_bytes(),
        };
        let f = Frame {
            data: {
                let mut d = [0; 8];
                d[..len as usize].copy_from_slice(&f.data[..len as usize]);
                d
            },
            ..f
        };
        let us = i * 1_000_000 / rate;
        candump_line(
            z.buf(),
            1_700_000_000 + (us / 1_000_000) as i64,
            (us % 1_000_000) as i64,
            "can0",
            &f,
        );
        z.line_added();
        if (i + 1) % per_flush == 0 {
            z.flush().expect("write");
        }
    }
    z.close().expect("write");
    let per = (cpu_time() - t0) / n as f64;
    println!(
        "zlog_cost: {n} frames, {rate} frames/s, flush {flush_ms} ms, level {level}: {:.2} us/frame = {:.3} % of one CPU per 1,000 frames/s; {:.2} bytes/frame on disk",
        per * 1e6,
        per * 1000.0 * 100.0,
        z.bytes_written as f64 / n as f64
    );
    let _ = std::fs::remove_dir_all(&dir);
}

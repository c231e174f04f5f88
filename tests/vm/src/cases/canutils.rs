// SPDX-License-Identifier: GPL-2.0
//! can-utils, unchanged (Debian's binaries from the host): cansend and
//! candump, candump's filters, cangen with a candump log file, extended and
//! remote frames. Each program's view is checked against a CAN_RAW socket's
//! (or the frames it sent), so a test fails if either side is wrong.

use socketcan::dump::Reader;
use socketcan::{CanAnyFrame, CanFrame, EmbeddedFrame, Frame};

use super::{portable_table, raw1};
use crate::canraw::{self, expect, ext, rtr_std, same, show, std};
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::tools::{self, TempDir, TOOL_LIMIT};
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    canutils_cansend_candump,
    canutils_candump_filter,
    canutils_cangen_candump_log,
    canutils_ext_and_remote,
];

/// Parses one line of candump's default output, e.g.
/// `  can0  123   [4]  DE AD BE EF` or `  can0  123   [0]  remote request`,
/// into the interface name and the frame.
fn parse_candump_line(line: &str) -> Result<(String, CanFrame), String> {
    let bad = || format!("unexpected candump line {line:?}");
    let t: Vec<&str> = line.split_whitespace().collect();
    let [iface, id, len, rest @ ..] = t.as_slice() else {
        return Err(bad());
    };
    let n: usize = len
        .strip_prefix('[')
        .and_then(|l| l.strip_suffix(']'))
        .and_then(|l| l.parse().ok())
        .filter(|&n| n <= 8)
        .ok_or_else(bad)?;
    let id_val = u32::from_str_radix(id, 16).map_err(|_| bad())?;
    let remote = rest == ["remote", "request"];
    let data = if remote {
        Vec::new()
    } else {
        rest.iter()
            .map(|b| u8::from_str_radix(b, 16).map_err(|_| bad()))
            .collect::<Result<Vec<u8>, String>>()?
    };
    ensure!(remote || data.len() == n, "{}: {n} bytes announced", bad());
    let frame = match (id.len(), remote) {
        (3, false) if id_val <= 0x7FF => std(id_val as u16, &data),
        (3, true) if id_val <= 0x7FF => rtr_std(id_val as u16, n),
        (8, false) if id_val <= 0x1FFF_FFFF => ext(id_val, &data),
        (8, true) if id_val <= 0x1FFF_FFFF => canraw::rtr_ext(id_val, n),
        _ => return Err(bad()),
    };
    Ok((iface.to_string(), frame))
}

/// Every line of candump's output, parsed; all must be on can0.
fn parse_candump(out: &str) -> Result<Vec<CanFrame>, String> {
    out.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let (iface, f) = parse_candump_line(l)?;
            ensure!(iface == "can0", "candump line on {iface}: {l:?}");
            Ok(f)
        })
        .collect()
}

/// Runs `candump ARGS` until it has printed `want.len()` frames (`-n`)
/// while `send` runs, and checks that they are `want`.
fn candump_sees(args: &[&str], send: impl FnOnce() -> TestResult, want: &[CanFrame]) -> TestResult {
    let n = want.len().to_string();
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["-n", &n]);
    let mut dump = tools::spawn("candump", &all, None)?;
    dump.wait_listening()?;
    send()?;
    let out = dump.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "candump {}: {}: {}",
        all.join(" "),
        out.status,
        out.stderr.trim()
    );
    let got = parse_candump(&out.stdout)?;
    ensure!(
        got.len() == want.len() && got.iter().zip(want).all(|(g, w)| same(g, w)),
        "candump {} printed {:?}, expected {:?}",
        all.join(" "),
        got.iter().map(show).collect::<Vec<_>>(),
        want.iter().map(show).collect::<Vec<_>>()
    );
    Ok(())
}

/// `cansend can0 123#DEADBEEF` is printed by candump and read by a CAN_RAW
/// socket.
fn canutils_cansend_candump(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let want = std(0x123, &[0xDE, 0xAD, 0xBE, 0xEF]);
    candump_sees(
        &["can0"],
        || tools::run_ok("cansend", &["can0", "123#DEADBEEF"]).map(drop),
        &[want],
    )?;
    expect(&rx, &want, "CAN_RAW socket")
}

/// `candump can0,123:7FF` prints only frames whose 11 low id bits are 0x123:
/// the standard frame 0x123 and, since the mask has no CAN_EFF_FLAG, the
/// extended frame 0x00000123 too.
fn canutils_candump_filter(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let frames = [
        (std(0x124, &[1]), false),
        (std(0x223, &[2]), false),
        (ext(0x124, &[3]), false),
        (std(0x123, &[4]), true),
        (ext(0x123, &[5]), true),
        (std(0x323, &[6]), false),
        (std(0x023, &[7]), false),
        (std(0x123, &[8]), true),
    ];
    let want: Vec<CanFrame> = frames.iter().filter(|f| f.1).map(|f| f.0).collect();
    candump_sees(
        &["can0,123:7FF"],
        || frames.iter().try_for_each(|(f, _)| canraw::send(&tx, f)),
        &want,
    )
}

/// A frame of a candump log as a classic frame.
fn classic(f: CanAnyFrame) -> Option<CanFrame> {
    match f {
        CanAnyFrame::Normal(d) => Some(d.into()),
        CanAnyFrame::Remote(r) => Some(r.into()),
        CanAnyFrame::Error(e) => Some(e.into()),
        CanAnyFrame::Fd(_) => None,
    }
}

/// `cangen can0 -n 100` logged by `candump -l`: the log file has 100
/// well-formed records (parsed by the socketcan crate) on can0, in time
/// order, with the frames a CAN_RAW socket received, in the same order.
fn canutils_cangen_candump_log(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let dir = TempDir::new("candump-log")?;
    let mut dump = tools::spawn("candump", &["-l", "can0", "-n", "100"], Some(dir.path()))?;
    dump.wait_listening()?;
    // 1 ms gap instead of the default 200: fast, and never more than a few
    // frames in flight.
    tools::run_ok("cangen", &["can0", "-n", "100", "-g", "1"])?;
    let out = dump.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "candump -l: {}: {}",
        out.status,
        out.stderr.trim()
    );
    let mut sent = Vec::new();
    for i in 0..100 {
        sent.push(canraw::recv(&rx).map_err(|e| format!("CAN_RAW socket, frame {i}: {e}"))?);
    }
    canraw::expect_quiet(&[("CAN_RAW socket", &rx)])?;

    let logs: Vec<_> = std::fs::read_dir(dir.path())
        .or_fail(dir.path().display())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("candump-") && n.ends_with(".log"))
        })
        .collect();
    let [log] = logs.as_slice() else {
        return Err(format!("expected one candump-*.log file, found {logs:?}"));
    };
    let mut last_t = 0;
    let mut n = 0;
    let reader = Reader::from_file(log).or_fail(log.display())?;
    for (i, rec) in reader.enumerate() {
        let rec = rec.map_err(|e| format!("{}: record {i}: {e}", log.display()))?;
        ensure!(rec.device == "can0", "record {i}: device {:?}", rec.device);
        ensure!(
            rec.t_us >= last_t && rec.t_us > 0,
            "record {i}: timestamp {} after {last_t}",
            rec.t_us
        );
        last_t = rec.t_us;
        let f = classic(rec.frame).ok_or_else(|| format!("record {i}: a CAN FD frame"))?;
        let want = sent
            .get(i)
            .ok_or_else(|| format!("record {i}: more than 100 records"))?;
        // cangen fills all 8 data bytes; only the first len are logged.
        ensure!(
            f.id_word() == want.id_word() && f.dlc() == want.dlc() && f.data() == want.data(),
            "record {i}: {} in the log, {} on the socket",
            show(&f),
            show(want)
        );
        n += 1;
    }
    ensure!(n == 100, "{}: {n} records, expected 100", log.display());
    Ok(())
}

/// `cansend can0 12345678#11` and `cansend can0 123#R`: an extended data
/// frame and a standard remote frame, as candump prints them and as a
/// CAN_RAW socket reads them.
fn canutils_ext_and_remote(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let want = [ext(0x1234_5678, &[0x11]), rtr_std(0x123, 0)];
    candump_sees(
        &["can0"],
        || {
            tools::run_ok("cansend", &["can0", "12345678#11"])?;
            tools::run_ok("cansend", &["can0", "123#R"]).map(drop)
        },
        &want,
    )?;
    canraw::expect_seq(&rx, &want, "CAN_RAW socket")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candump_lines() {
        let (i, f) = parse_candump_line("  can0  123   [4]  DE AD BE EF").unwrap();
        assert_eq!(i, "can0");
        assert!(same(&f, &std(0x123, &[0xDE, 0xAD, 0xBE, 0xEF])));
        let (_, f) = parse_candump_line("  can0  12345678   [1]  11").unwrap();
        assert!(same(&f, &ext(0x1234_5678, &[0x11])));
        let (_, f) = parse_candump_line("  can0  123   [0]  remote request").unwrap();
        assert!(same(&f, &rtr_std(0x123, 0)));
        let (_, f) = parse_candump_line("  can0  7FF   [0] ").unwrap();
        assert!(same(&f, &std(0x7FF, &[])));
        assert!(parse_candump_line("  can0  123   [2]  DE").is_err());
        assert!(parse_candump_line("  can0  800   [0]").is_err());
        assert!(parse_candump_line("garbage").is_err());
    }
}

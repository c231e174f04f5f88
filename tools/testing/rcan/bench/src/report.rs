// SPDX-License-Identifier: GPL-2.0
//! Per-stack results and the final summary table with the ratios
//! ours/mainline and the target verdicts.
//!
//! The benchmark never fails on a missed target: it only says so.

use std::fmt::Write as _;

use crate::stack::Stack;

/// Target (a): ours must move at least this many times mainline's frames/s.
pub const TARGET_THROUGHPUT: f64 = 1.2;
/// Target (b): ours' cost per frame with 1,000 receivers at most this many
/// times its cost with 1.
pub const TARGET_FANOUT: f64 = 1.5;

/// Throughput medians.
#[derive(Clone, Copy, Debug)]
pub struct Throughput {
    /// Undisturbed rate: median of the runs' `ThroughputRun::fps_fast`.
    pub fps: f64,
    /// Median of the runs' whole-run rates.
    pub fps_run: f64,
    /// Frames lost over all measured runs.
    pub lost: u64,
    /// Out-of-order/stale/misdelivered frames over all measured runs.
    pub odd: u64,
    pub runs: usize,
}

/// Fan-out medians for one receiver count.
#[derive(Clone, Copy, Debug)]
pub struct Fanout {
    pub receivers: usize,
    /// Undisturbed cost: median of the runs' `FanoutRun::ns_fast`.
    pub ns_per_frame: f64,
    /// Median of the runs' whole-run costs.
    pub ns_run: f64,
    /// Median time to open, filter and bind the receivers, in ms.
    pub setup_ms: f64,
    pub lost: u64,
    pub odd: u64,
    pub runs: usize,
}

/// Latency medians over runs, in ns.
#[derive(Clone, Copy, Debug)]
pub struct Latency {
    pub p50: u64,
    pub p99: u64,
    /// Largest latency seen in any measured run.
    pub max: u64,
    pub lost: u64,
    pub odd: u64,
    pub runs: usize,
}

/// Everything measured on one stack (medians over all its runs).
#[derive(Debug)]
pub struct StackResult {
    pub stack: Stack,
    /// Setup and workload failures, in the order they happened.
    pub errors: Vec<String>,
    pub throughput: Option<Throughput>,
    /// By ascending receiver count.
    pub fanout: Vec<Fanout>,
    pub latency: Option<Latency>,
}

impl StackResult {
    fn fan(&self, receivers: usize) -> Option<&Fanout> {
        self.fanout.iter().find(|f| f.receivers == receivers)
    }

    /// Cost with the most receivers divided by the cost with one.
    pub fn fanout_ratio(&self) -> Option<(usize, f64)> {
        let one = self.fan(1)?;
        let most = self
            .fanout
            .iter()
            .filter(|f| f.receivers > 1)
            .max_by_key(|f| f.receivers)?;
        Some((most.receivers, most.ns_per_frame / one.ns_per_frame))
    }
}

fn cell_f(v: Option<f64>, prec: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.prec$}"))
}

fn ratio(ours: Option<f64>, mainline: Option<f64>) -> String {
    match (ours, mainline) {
        (Some(o), Some(m)) if m > 0.0 => format!("{:.2}x", o / m),
        _ => "-".to_string(),
    }
}

/// "lo-hi x" of per-round ratios; "-" with fewer than two rounds.
pub fn ratio_range(v: &[f64]) -> String {
    let lo = v.iter().copied().reduce(f64::min);
    let hi = v.iter().copied().reduce(f64::max);
    match (lo, hi) {
        (Some(lo), Some(hi)) if v.len() > 1 => format!("{lo:.2}-{hi:.2}x"),
        _ => "-".to_string(),
    }
}

/// " (per round lo-hi x)", or nothing with fewer than two rounds.
fn per_round(v: &[f64]) -> String {
    match ratio_range(v).as_str() {
        "-" => String::new(),
        x => format!(" (per round {x})"),
    }
}

fn verdict(met: Option<bool>) -> &'static str {
    match met {
        Some(true) => "target met",
        Some(false) => "target missed",
        None => "target not measured",
    }
}

/// The summary: one row per figure, a column per stack, the ratio
/// ours/mainline of the medians over all runs, and the range of the same
/// ratio round by round (each round measures both stacks back to back, so
/// that range shows how far the host's noise moves it); then the target
/// verdicts and any errors.
pub fn summary(results: &[StackResult], rounds: &[Vec<StackResult>], header: &str) -> String {
    let pick = |rs: &[StackResult], st: Stack| rs.iter().position(|r| r.stack == st);
    let m = pick(results, Stack::Mainline).map(|i| &results[i]);
    let o = pick(results, Stack::Ours).map(|i| &results[i]);
    // Ratios ours/mainline of figure `f`, round by round.
    let round_ratios = |f: &dyn Fn(&StackResult) -> Option<f64>| -> Vec<f64> {
        rounds
            .iter()
            .filter_map(|rs| {
                let mv = pick(rs, Stack::Mainline).and_then(|i| f(&rs[i]))?;
                let ov = pick(rs, Stack::Ours).and_then(|i| f(&rs[i]))?;
                (mv > 0.0).then(|| ov / mv)
            })
            .collect()
    };
    let mut s = String::new();
    let _ = writeln!(s, "=== rcan-bench summary ===");
    let _ = writeln!(s, "{header}");
    let _ = writeln!(
        s,
        "{:<36} {:>10} {:>10} {:>14} {:>12}",
        "figure (medians)", "mainline", "ours", "ours/mainline", "per round"
    );
    let mut row =
        |name: &str, f: &dyn Fn(&StackResult) -> Option<f64>, prec: usize, ratios: bool| {
            let mv = m.and_then(f);
            let ov = o.and_then(f);
            let (r, range) = if ratios {
                (ratio(ov, mv), ratio_range(&round_ratios(f)))
            } else {
                (String::new(), String::new())
            };
            let line = format!(
                "{:<36} {:>10} {:>10} {:>14} {:>12}",
                name,
                cell_f(mv, prec),
                cell_f(ov, prec),
                r,
                range
            );
            let _ = writeln!(s, "{}", line.trim_end());
        };
    row(
        "(a) frames/s, undisturbed",
        &|r| r.throughput.map(|t| t.fps),
        0,
        true,
    );
    row(
        "(a) frames/s, whole runs",
        &|r| r.throughput.map(|t| t.fps_run),
        0,
        true,
    );
    row(
        "(a) frames lost (all runs)",
        &|r| r.throughput.map(|t| t.lost as f64),
        0,
        false,
    );
    let mut counts: Vec<usize> = results
        .iter()
        .flat_map(|r| r.fanout.iter().map(|f| f.receivers))
        .collect();
    counts.sort_unstable();
    counts.dedup();
    for &n in &counts {
        row(
            &format!("(b) {n} rcv, ns/frame, undisturbed"),
            &move |r| r.fan(n).map(|f| f.ns_per_frame),
            0,
            true,
        );
    }
    for &n in &counts {
        row(
            &format!("(b) {n} rcv, ns/frame, whole runs"),
            &move |r| r.fan(n).map(|f| f.ns_run),
            0,
            true,
        );
    }
    if let Some(&most) = counts.last() {
        row(
            &format!("(b) {most} rcv, socket setup, ms"),
            &move |r| r.fan(most).map(|f| f.setup_ms),
            1,
            true,
        );
    }
    row(
        "(b) frames lost (all runs)",
        &|r| (!r.fanout.is_empty()).then(|| r.fanout.iter().map(|f| f.lost as f64).sum()),
        0,
        false,
    );
    if let Some(&most) = counts.last().filter(|&&n| n > 1) {
        row(
            &format!("(b) cost {most} : 1 rcv, undisturbed"),
            &|r| r.fanout_ratio().map(|x| x.1),
            2,
            true,
        );
    }
    row(
        "(c) latency p50, us",
        &|r| r.latency.map(|l| l.p50 as f64 / 1e3),
        1,
        true,
    );
    row(
        "(c) latency p99, us",
        &|r| r.latency.map(|l| l.p99 as f64 / 1e3),
        1,
        true,
    );
    row(
        "(c) latency max, us",
        &|r| r.latency.map(|l| l.max as f64 / 1e3),
        1,
        true,
    );
    row(
        "(c) frames lost (all runs)",
        &|r| r.latency.map(|l| l.lost as f64),
        0,
        false,
    );

    let _ = writeln!(s);
    // (a)
    let a = match (o.and_then(|r| r.throughput), m.and_then(|r| r.throughput)) {
        (Some(ot), Some(mt)) if mt.fps > 0.0 => {
            let x = ot.fps / mt.fps;
            format!(
                "ours/mainline = {x:.2}x{}, want >= {TARGET_THROUGHPUT:.1}x: {}",
                per_round(&round_ratios(&|r| r.throughput.map(|t| t.fps))),
                verdict(Some(x >= TARGET_THROUGHPUT))
            )
        }
        _ => format!("needs both stacks: {}", verdict(None)),
    };
    let _ = writeln!(s, "(a) throughput: {a}");
    // (b)
    for r in results {
        if let Some((n, x)) = r.fanout_ratio() {
            let ratios: Vec<f64> = rounds
                .iter()
                .filter_map(|rs| pick(rs, r.stack).and_then(|i| rs[i].fanout_ratio()))
                .map(|x| x.1)
                .collect();
            let range = per_round(&ratios);
            let tail = if r.stack == Stack::Ours {
                format!(
                    ", want <= {TARGET_FANOUT:.1}x: {}",
                    verdict((n >= 1000).then_some(x <= TARGET_FANOUT))
                )
            } else {
                " (reference)".to_string()
            };
            let _ = writeln!(
                s,
                "(b) fan-out, {}: cost {n} : 1 receivers = {x:.2}x{range}{tail}",
                r.stack
            );
        }
    }
    if o.and_then(StackResult::fanout_ratio).is_none() {
        let _ = writeln!(s, "(b) fan-out, ours: {}", verdict(None));
    }
    // (c)
    let c = match (o.and_then(|r| r.latency), m.and_then(|r| r.latency)) {
        (Some(ol), Some(ml)) => format!(
            "ours p99 {:.1} us vs mainline p99 {:.1} us = {:.2}x{}, \
             want ours <= mainline: {}",
            ol.p99 as f64 / 1e3,
            ml.p99 as f64 / 1e3,
            ol.p99 as f64 / ml.p99.max(1) as f64,
            per_round(&round_ratios(&|r| r.latency.map(|l| l.p99 as f64))),
            verdict(Some(ol.p99 <= ml.p99))
        ),
        _ => format!("needs both stacks: {}", verdict(None)),
    };
    let _ = writeln!(s, "(c) latency: {c}");

    for r in results {
        for e in &r.errors {
            let _ = writeln!(s, "ERROR {}: {e}", r.stack);
        }
        let odd = r.throughput.map_or(0, |t| t.odd)
            + r.fanout.iter().map(|f| f.odd).sum::<u64>()
            + r.latency.map_or(0, |l| l.odd);
        if odd > 0 {
            let _ = writeln!(
                s,
                "NOTE {}: {odd} frame(s) arrived out of order, late, stale or at the wrong socket",
                r.stack
            );
        }
    }
    s
}

// SPDX-License-Identifier: GPL-2.0
//! Property tests of the DSOR time services (`rcan_core::timesvc`): the
//! time frame's encoding, the redundant service's takeover state machine
//! against its one-line rule, and the 1 Hz ticker (realtime timer plus
//! monotonic watchdog) in a simulation with clock steps and late callbacks.

use proptest::prelude::*;
use rcan_core::frame::CanFrame;
use rcan_core::timesvc::*;

const S: i64 = NSEC_PER_SEC;
const MS: i64 = 1_000_000;

// ---------------------------------------------------------------------------
// Time frame
// ---------------------------------------------------------------------------

fn vehicle() -> impl Strategy<Value = u32> {
    (0u32..16).prop_map(|v| v << 4)
}

proptest! {
    #[test]
    fn frame_roundtrip(secs in any::<i64>(), source in any::<u8>(), v in vehicle()) {
        let t = TimeFrame::for_second(secs, source);
        let f = t.encode(v);
        prop_assert_eq!(f.can_id, v);
        prop_assert_eq!(f.len, 8);
        prop_assert_eq!(&f.data[..4], &((secs as u64 & 0xffff_ffff) as u32).to_be_bytes()[..]);
        prop_assert_eq!(f.data[4], source);
        prop_assert_eq!(&f.data[5..], &[0u8; 3][..]);
        prop_assert_eq!(TimeFrame::decode(&f, v), Some(t));
        prop_assert_eq!(CanFrame::from_bytes(&f.to_bytes()), f);
    }

    /// Any frame that is not a standard data frame with exactly the
    /// vehicle identifier and DLC 8 is not a time frame.
    #[test]
    fn decode_rejects(can_id in any::<u32>(), len in 0u8..=8, data in any::<[u8; 8]>(), v in vehicle()) {
        let f = CanFrame { can_id, len, data, ..CanFrame::default() };
        let ok = can_id == v && len == 8;
        prop_assert_eq!(TimeFrame::decode(&f, v).is_some(), ok);
        prop_assert_eq!(is_time_id(&f, v), can_id == v);
    }

    /// The 2^32 wrap is resolved for any receiver clock within 68 years.
    #[test]
    fn unwrap_near(secs in 0i64..(1 << 40), err in -(1i64 << 31) + 1..(1i64 << 31)) {
        let t = TimeFrame::for_second(secs, 0);
        prop_assert_eq!(t.unix_seconds(secs + err), secs);
    }

    #[test]
    fn vehicle_rule(v in any::<u32>()) {
        prop_assert_eq!(vehicle_valid(v), v < 256 && v % 16 == 0);
    }
}

// ---------------------------------------------------------------------------
// Takeover state machine
// ---------------------------------------------------------------------------

/// Arrival times of another source's frames: runs of frames one second
/// apart (a working GPS node, with its own phase) separated by silences.
fn foreign_frames() -> impl Strategy<Value = Vec<i64>> {
    prop::collection::vec((0i64..8 * S, 0usize..12, 0i64..20 * MS), 0..12).prop_map(|runs| {
        let mut t = 0;
        let mut out = Vec::new();
        for (gap, n, jitter) in runs {
            t += gap;
            for _ in 0..n {
                t += S + jitter - 10 * MS;
                out.push(t);
            }
        }
        out
    })
}

/// The newest of `frames` (sorted) at or before `now`.
fn last_at(frames: &[i64], now: i64) -> Option<i64> {
    frames.iter().copied().filter(|&f| f <= now).max()
}

struct Run {
    ticks: Vec<(i64, Decision)>,
}

/// Feeds boundaries `phase + k s` (k = 1..=n) to a service started at 0.
fn run(frames: &[i64], phase: i64, n: i64, timeout: impl Fn(usize) -> i64) -> Run {
    let mut m = Takeover::new(0);
    let mut ticks = Vec::new();
    for k in 1..=n {
        let now = phase + k * S;
        let d = m.tick(now, last_at(frames, now), timeout(ticks.len()));
        ticks.push((now, d));
    }
    Run { ticks }
}

proptest! {
    /// For a constant timeout the service sends at a boundary if and only
    /// if no foreign frame (nor the start) lies within the timeout before
    /// it; the transitions are named exactly at the changes.
    #[test]
    fn takeover_rule(frames in foreign_frames(), phase in 0..S, to_ms in MIN_TIMEOUT_MS..8000) {
        let to = i64::from(to_ms) * MS;
        let r = run(&frames, phase, 80, |_| to);
        let mut was_sending = false;
        for &(now, d) in &r.ticks {
            let since = last_at(&frames, now).map_or(0, |f| f.max(0));
            let quiet = now - since >= to;
            prop_assert_eq!(d.sends(), quiet, "at {} last {:?}", now, last_at(&frames, now));
            prop_assert_eq!(d == Decision::TakeOver, quiet && !was_sending);
            prop_assert_eq!(d == Decision::HandBack, !quiet && was_sending);
            was_sending = d.sends();
        }
    }

    /// Takeover comes at the first boundary at least the timeout after the
    /// last foreign frame: never earlier, never a second later.
    #[test]
    fn takeover_latency(frames in foreign_frames(), phase in 0..S, to_ms in MIN_TIMEOUT_MS..8000) {
        let to = i64::from(to_ms) * MS;
        let r = run(&frames, phase, 80, |_| to);
        for &(now, d) in &r.ticks {
            if d == Decision::TakeOver {
                let since = last_at(&frames, now).map_or(0, |f| f.max(0));
                prop_assert!(now - since >= to);
                prop_assert!(now - since < to + S, "took over {} ns after", now - since);
            }
        }
    }

    /// Two time frames in one second happen only in the second in which
    /// the other source's first frame after a takeover arrives; the next
    /// boundary is silent. A source that sends at least once per timeout
    /// never hears us.
    #[test]
    fn flap_window(frames in foreign_frames(), phase in 0..S, to_ms in MIN_TIMEOUT_MS..8000) {
        let to = i64::from(to_ms) * MS;
        let r = run(&frames, phase, 80, |_| to);
        let mut last_takeover = None;
        for (i, &(now, d)) in r.ticks.iter().enumerate() {
            if d == Decision::TakeOver {
                last_takeover = Some(now);
            }
            if !d.sends() {
                continue;
            }
            let in_second: Vec<i64> =
                frames.iter().copied().filter(|&f| f > now && f < now + S).collect();
            if in_second.is_empty() {
                continue;
            }
            let t0 = last_takeover.expect("sending implies a takeover");
            // No foreign frame between the takeover and this second.
            prop_assert!(!frames.iter().any(|&f| f > t0 && f <= now));
            if let Some(&(_, next)) = r.ticks.get(i + 1) {
                prop_assert_eq!(next, Decision::HandBack);
            }
        }
        // A source whose frames are never more than the timeout apart
        // (from the start on) keeps us silent.
        let mut prev = 0;
        let mut covered_until = 0;
        for &f in &frames {
            if f - prev >= to {
                break;
            }
            prev = f;
            covered_until = f + to;
        }
        for &(now, d) in &r.ticks {
            if now < covered_until {
                prop_assert!(!d.sends(), "sent at {} although covered until {}", now, covered_until);
            }
        }
    }

    /// Changing the timeout at run time never hands back without a foreign
    /// frame, and never sends within the timeout in force after one.
    #[test]
    fn timeout_changes(frames in foreign_frames(), phase in 0..S,
                       tos in prop::collection::vec(MIN_TIMEOUT_MS..8000, 80)) {
        let r = run(&frames, phase, 80, |i| i64::from(tos[i]) * MS);
        let mut prev_now = phase;
        for (i, &(now, d)) in r.ticks.iter().enumerate() {
            let new_foreign = frames.iter().any(|&f| f > prev_now && f <= now);
            if d == Decision::HandBack {
                prop_assert!(new_foreign, "handback at {} without a foreign frame", now);
            }
            if let Some(f) = last_at(&frames, now) {
                if d == Decision::TakeOver {
                    prop_assert!(now - f >= i64::from(tos[i]) * MS);
                }
            }
            prev_now = now;
        }
    }
}

#[test]
fn racing_frame_counts_as_seen() {
    let mut m = Takeover::new(0);
    assert_eq!(m.tick(10 * S, Some(10 * S + 1), 2 * S), Decision::Silent);
    assert_eq!(m.tick(11 * S, Some(10 * S + 1), 2 * S), Decision::Silent);
    assert_eq!(m.tick(13 * S, Some(10 * S + 1), 2 * S), Decision::TakeOver);
    assert_eq!(m.role(), Role::Active);
}

// ---------------------------------------------------------------------------
// The 1 Hz ticker with clock steps
// ---------------------------------------------------------------------------

/// Most a simulated callback runs after its timer expired. The two timers'
/// callbacks run one after the other (as on one CPU's softirq), so a frame
/// can be up to twice this late: its own delay plus the watchdog's.
const MAX_LAT: i64 = 20 * MS;

/// CLOCK_REALTIME as a function of CLOCK_MONOTONIC: an initial offset and
/// steps (settimeofday) at given monotonic times.
struct Clock {
    offset: i64,
    /// (monotonic time, delta), sorted by time.
    steps: Vec<(i64, i64)>,
}

impl Clock {
    fn offset_at(&self, m: i64) -> i64 {
        self.offset
            + self
                .steps
                .iter()
                .filter(|&&(t, _)| t <= m)
                .map(|&(_, d)| d)
                .sum::<i64>()
    }

    fn real(&self, m: i64) -> i64 {
        m + self.offset_at(m)
    }

    /// When an absolute realtime timer for `r`, armed at `from`, fires:
    /// the first monotonic time when the realtime clock reads `r` or more
    /// (a forward step past `r` fires it at the step, as clock_was_set()
    /// does).
    fn fire_time(&self, from: i64, r: i64) -> i64 {
        let mut a = from;
        let mut off = self.offset_at(from);
        for &(t, d) in self.steps.iter().filter(|&&(t, _)| t > from) {
            let cand = a.max(r - off);
            if cand < t {
                return cand;
            }
            a = t;
            off += d;
        }
        a.max(r - off)
    }
}

#[derive(Debug, Clone, Copy)]
struct Sent {
    mono: i64,
    second: i64,
    /// The callback's `TimerFire::missed`.
    missed: u64,
    /// Its delay after the realtime timer expired (the realtime clock
    /// first read the expiry, or a forward step passed it): its own
    /// latency, plus a watchdog callback's if that ran first.
    late: i64,
}

/// Runs the ticker for `horizon` ns of monotonic time; `lat` gives each
/// callback's delay after its expiry, cyclically. Like the kernel's
/// ticker, only the realtime timer's callback (and the start) record the
/// expiry's monotonic due time; the watchdog re-arms the realtime timer
/// without it.
fn simulate(clock: &Clock, lat: &[i64], horizon: i64) -> Vec<Sent> {
    let start = arm(clock.real(0), 0);
    let (mut rt, mut wd) = (start.real, start.watchdog_mono);
    let mut due = start.due_mono;
    // When `rt` was set: the realtime timer expires at the first monotonic
    // time after this at which the clock reads `rt`.
    let mut rt_set = 0;
    let mut now = 0;
    let mut sent = Vec::new();
    for i in 0.. {
        let t_rt = clock.fire_time(now, rt);
        let is_rt = t_rt <= wd;
        let t = if is_rt { t_rt } else { wd };
        if t > horizon {
            break;
        }
        let l = lat[i % lat.len()];
        let m = t + l;
        now = m;
        let real = clock.real(m);
        if is_rt {
            let f = on_timer(real, m, rt, due);
            if let Some(second) = f.second {
                assert_eq!(second, second_of(real));
                sent.push(Sent {
                    mono: m,
                    second,
                    missed: f.missed,
                    late: m - clock.fire_time(rt_set, rt),
                });
            } else {
                assert_eq!(f.missed, 0);
            }
            rt = f.next.real;
            rt_set = m;
            due = f.next.due_mono;
            wd = f.next.watchdog_mono;
        } else {
            let w = on_watchdog(real, m, rt);
            if let Some(r) = w.rearm_real {
                rt = r;
                rt_set = m;
            }
            wd = w.watchdog_mono;
        }
    }
    sent
}

/// Clock steps at least 5 s apart, forward or back, from a millisecond to
/// a thousand seconds.
fn steps() -> impl Strategy<Value = Vec<(i64, i64)>> {
    prop::collection::vec(
        (
            5 * S..9 * S,
            1i64..1_000_000,
            prop::bool::ANY,
            prop::bool::ANY,
        ),
        0..8,
    )
    .prop_map(|v| {
        let mut t = 0;
        v.into_iter()
            .map(|(gap, ms, big, back)| {
                t += gap;
                let mag = if big { ms * MS } else { (ms % 1500) * MS };
                (t, if back { -mag.max(MS) } else { mag.max(MS) })
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// Between two frames with no clock step near them, exactly one second
    /// passes and the next second is named; any two consecutive frames are
    /// at most 2 s + slack apart; frames less than a second apart need a
    /// forward step between them, and a forward step causes at most one
    /// extra frame (no catch-up burst).
    #[test]
    fn ticker_with_steps(
        phase in 0..S,
        steps in steps(),
        lat in prop::collection::vec(0..=MAX_LAT, 1..16),
    ) {
        let clock = Clock { offset: 1_700_000_000 * S + phase, steps };
        let horizon = 70 * S;
        let sent = simulate(&clock, &lat, horizon);
        prop_assert!(sent.len() >= 30, "only {} frames in 70 s", sent.len());
        let step_in = |a: i64, b: i64| clock.steps.iter().filter(move |&&(t, _)| t > a && t <= b);
        for w in sent.windows(2) {
            let (a, b) = (w[0], w[1]);
            let gap = b.mono - a.mono;
            prop_assert!(gap <= 2 * S + WATCHDOG_SLACK_NS + 2 * MAX_LAT, "gap {} ns", gap);
            if step_in(a.mono - S, b.mono).next().is_none() {
                prop_assert!((gap - S).abs() <= 2 * MAX_LAT, "gap {} ns without a step", gap);
                prop_assert_eq!(b.second, a.second + 1);
            }
            let forward = step_in(a.mono - 2 * MAX_LAT, b.mono).any(|&(_, d)| d > 0);
            if !forward {
                prop_assert!(gap >= S - 2 * MAX_LAT, "gap {} ns without a forward step", gap);
            }
        }
        // Callbacks at most MAX_LAT late miss no second, whatever the
        // steps: the seconds a forward step jumps over are not "missed".
        for s in &sent {
            prop_assert_eq!(s.missed, 0, "{:?}", s);
        }
        for &(t, d) in &clock.steps {
            let n = sent.iter().filter(|s| s.mono >= t && s.mono < t + 3 * S).count();
            prop_assert!(n <= 4, "{} frames in the 3 s after a step", n);
            if d > 0 {
                // A frame was due before the step: it goes out at the step,
                // naming the new current second.
                if let Some(first) = sent.iter().find(|s| s.mono >= t) {
                    let due = clock.real(t) >= next_boundary(clock.real(t) - d);
                    if due {
                        prop_assert!(first.mono <= t + 2 * MAX_LAT);
                        prop_assert_eq!(first.second, second_of(clock.real(first.mono)));
                    }
                }
            }
        }
    }

    /// Without steps every second is named once, in order, a second apart.
    #[test]
    fn ticker_steady(phase in 0..S, lat in prop::collection::vec(0..=MAX_LAT, 1..16)) {
        let clock = Clock { offset: 1_700_000_000 * S + phase, steps: Vec::new() };
        let sent = simulate(&clock, &lat, 40 * S);
        prop_assert!(sent.len() >= 39);
        for w in sent.windows(2) {
            prop_assert_eq!(w[1].second, w[0].second + 1);
        }
    }
}

/// Callback delays of up to 4 s, some of them whole seconds exactly.
fn big_latencies() -> impl Strategy<Value = Vec<i64>> {
    prop::collection::vec(
        prop_oneof![0..=MAX_LAT, 0..4 * S, (0i64..4).prop_map(|k| k * S)],
        1..16,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// Late callbacks without clock steps: each frame names the second it
    /// is sent in, and the seconds between two consecutive frames' that no
    /// frame named are exactly what the later one's callback counted as
    /// missed, its whole seconds of delay. So frames plus missed seconds
    /// account for every second from the first frame to the last.
    #[test]
    fn ticker_late_exact(phase in 0..S, lat in big_latencies()) {
        let clock = Clock { offset: 1_700_000_000 * S + phase, steps: Vec::new() };
        let sent = simulate(&clock, &lat, 60 * S);
        prop_assert!(sent.len() >= 10, "only {} frames in 60 s", sent.len());
        for w in sent.windows(2) {
            let (a, b) = (w[0], w[1]);
            prop_assert_eq!(b.second - a.second - 1, b.missed as i64, "{:?} then {:?}", a, b);
            prop_assert_eq!(b.missed as i64, b.late / S, "{:?}", b);
        }
        let missed: u64 = sent[1..].iter().map(|s| s.missed).sum();
        let span = sent[sent.len() - 1].second - sent[0].second + 1;
        prop_assert_eq!(sent.len() as i64 + missed as i64, span);
    }

    /// Late callbacks and clock steps: between two frames with no step
    /// between them the accounting is exact as without steps; across a
    /// step a callback counts at most its whole seconds of delay after
    /// the expiry (a forward step's seconds are never counted as missed),
    /// except after a backward and a forward step within 10 s, where it
    /// may count more (never fewer).
    #[test]
    fn ticker_late_with_steps(phase in 0..S, steps in steps(), lat in big_latencies()) {
        let clock = Clock { offset: 1_700_000_000 * S + phase, steps };
        let sent = simulate(&clock, &lat, 70 * S);
        for w in sent.windows(2) {
            let (a, b) = (w[0], w[1]);
            if !clock.steps.iter().any(|&(t, _)| t > a.mono && t <= b.mono) {
                prop_assert_eq!(b.second - a.second - 1, b.missed as i64, "{:?} then {:?}", a, b);
            }
        }
        for (i, s) in sent.iter().enumerate() {
            // A stale due time (watchdog re-arm after a backward step) can
            // only make the monotonic count too large; the realtime count
            // then bounds it unless a forward step also came in between.
            let recent = |d: i64| clock.steps.iter().any(|&(t, dd)| {
                (dd > 0) == (d > 0) && t <= s.mono && t > s.mono - 10 * S
            });
            if !(recent(1) && recent(-1)) {
                prop_assert!(s.missed as i64 <= s.late / S, "frame {}: {:?}", i, s);
            }
        }
    }
}

/// The failure that motivated the missed-seconds counter (VM test
/// rtime_takeover_handback on a loaded host): a callback 1.44 s late names
/// the second after the one it was armed for, and counts that one missed.
#[test]
fn late_by_1_44_s() {
    let clock = Clock {
        offset: 1_795_915_720 * S,
        steps: Vec::new(),
    };
    let mut lat = vec![2 * MS; 9];
    lat.push(1_437_851_531);
    let sent = simulate(&clock, &lat, 12 * S);
    let w = sent
        .windows(2)
        .find(|w| w[1].second != w[0].second + 1)
        .expect("a jump");
    assert_eq!(w[1].second, w[0].second + 2);
    assert_eq!(w[1].missed, 1);
    assert_eq!(sent.iter().map(|s| s.missed).sum::<u64>(), 1);
}

/// The design's worst case: a backward step just under a second plus the
/// watchdog's slack gives the longest gap, just under 2 s + slack.
#[test]
fn backward_step_worst_case() {
    let clock = Clock {
        offset: 1_700_000_000 * S,
        steps: vec![(10 * S + MS, -(S + WATCHDOG_SLACK_NS - MS))],
    };
    let sent = simulate(&clock, &[0], 20 * S);
    let max_gap = sent
        .windows(2)
        .map(|w| w[1].mono - w[0].mono)
        .max()
        .unwrap();
    assert!(max_gap > 2 * S, "{max_gap}");
    assert!(max_gap <= 2 * S + WATCHDOG_SLACK_NS, "{max_gap}");
    // And a big backward step is caught by the watchdog, not waited out.
    let clock = Clock {
        offset: 1_700_000_000 * S,
        steps: vec![(10 * S + MS, -1000 * S)],
    };
    let sent = simulate(&clock, &[0], 20 * S);
    let max_gap = sent
        .windows(2)
        .map(|w| w[1].mono - w[0].mono)
        .max()
        .unwrap();
    assert!(max_gap <= 2 * S + WATCHDOG_SLACK_NS, "{max_gap}");
}

/// A backward step between the realtime timer's expiry and its callback
/// (found by `ticker_with_steps`): the callback must not announce the old
/// second again 8 ms before announcing the next one.
#[test]
fn step_back_between_expiry_and_callback() {
    let clock = Clock {
        offset: 1_700_000_000 * S + 959_359_124,
        steps: vec![
            (7_350_693_905, 1_494 * MS),
            (14_618_895_418, 12 * MS),
            (22_768_892_458, 194_544 * MS),
            (30_990_640_877, -8 * MS),
        ],
    };
    let sent = simulate(&clock, &[0, 0, 0, 0, 1, 0, 0, 0, 0, 0], 40 * S);
    // The earlier (forward) steps only set the phase up.
    for w in sent.windows(2).filter(|w| w[0].mono > 29 * S) {
        assert!(w[1].mono - w[0].mono >= S - MAX_LAT, "{:?}", w);
        assert!(w[1].second > w[0].second, "{:?}", w);
    }
}

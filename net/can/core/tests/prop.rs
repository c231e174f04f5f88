// SPDX-License-Identifier: GPL-2.0
//! Property tests of rcan-core against reference models of the thesis'
//! arbitration field (thesis 5.2.2, figure 5-5), filters (5.2.4), frames,
//! addresses and loopback helpers (5.3.5).

use proptest::prelude::*;
use rcan_core::arb::*;
use rcan_core::canloop::{DropRate, FrameDump};
use rcan_core::filter::{ArbFilter, Receiver};
use rcan_core::frame::{CanFrame, FrameError};
use rcan_core::sockaddr::{self, AddrError, SockaddrArb, AF_CAN, SOCKADDR_CANARB_LEN};

const EXT_BITS: u32 = 0x001F_FFF8;

fn std_arb(rtr: impl Strategy<Value = bool>) -> impl Strategy<Value = Arb> {
    (0u32..=CAN_SFF_MASK, rtr).prop_map(|(id, rtr)| Arb::std(id, rtr).unwrap())
}

fn ext_arb(rtr: impl Strategy<Value = bool>) -> impl Strategy<Value = Arb> {
    (0u32..=CAN_EFF_MASK, rtr).prop_map(|(id, rtr)| Arb::ext(id, rtr).unwrap())
}

/// Every valid arbitration field, with both formats equally likely.
fn any_arb() -> impl Strategy<Value = Arb> {
    prop_oneof![std_arb(any::<bool>()), ext_arb(any::<bool>())]
}

/// Reference validity of a raw field (figure 5-5).
fn raw_valid(raw: u32) -> bool {
    raw & 1 == 0 && (raw & CAN_IDE != 0 || raw & EXT_BITS == 0)
}

/// Bit-by-bit reference of filter matching (thesis 5.2.4).
fn ref_matches(arb: u32, mask: u32, frame: u32) -> bool {
    (1..32).all(|bit| {
        let dont_care = (mask >> bit) & 1 == 1;
        dont_care || (arb >> bit) & 1 == (frame >> bit) & 1
    })
}

/// Reference dump format of `FrameDump`.
fn ref_dump(f: &CanFrame) -> String {
    if f.can_id & CAN_ERR_FLAG != 0 {
        return format!("ERR {:08X}", f.can_id);
    }
    let dlc = usize::from(f.len).min(8);
    let mut s = if f.can_id & CAN_EFF_FLAG != 0 {
        format!("EXT {:08X} [{dlc}]", f.can_id & CAN_EFF_MASK)
    } else {
        format!("STD {:03X} [{dlc}]", f.can_id & CAN_SFF_MASK)
    };
    if f.can_id & CAN_RTR_FLAG != 0 {
        s.push_str(" remote");
    } else {
        for b in &f.data[..dlc] {
            s.push_str(&format!(" {b:02X}"));
        }
    }
    s
}

fn any_frame() -> impl Strategy<Value = CanFrame> {
    any::<[u8; 16]>().prop_map(|b| CanFrame::from_bytes(&b))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    // ---- arb.rs ----

    #[test]
    fn arb_can_id_round_trip(a in any_arb()) {
        prop_assert_eq!(Arb::from_can_id(a.to_can_id()), Some(a));
        prop_assert_eq!(Arb::from_raw(a.raw()), Ok(a));
    }

    #[test]
    fn arb_fields(a in any_arb()) {
        let c = a.to_can_id();
        prop_assert_eq!(a.is_ext(), c & CAN_EFF_FLAG != 0);
        prop_assert_eq!(a.is_rtr(), c & CAN_RTR_FLAG != 0);
        prop_assert_eq!(c & CAN_ERR_FLAG, 0);
        if a.is_ext() {
            prop_assert_eq!(a.id(), a.raw() >> 3);
            prop_assert_eq!(Arb::ext(a.id(), a.is_rtr()), Ok(a));
        } else {
            prop_assert_eq!(a.id(), a.raw() >> 21);
            prop_assert_eq!(Arb::std(a.id(), a.is_rtr()), Ok(a));
        }
    }

    #[test]
    fn can_id_round_trip(
        ext in any::<bool>(),
        rtr in any::<bool>(),
        id in any::<u32>(),
    ) {
        let flags = if rtr { CAN_RTR_FLAG } else { 0 };
        let c = if ext {
            CAN_EFF_FLAG | flags | (id & CAN_EFF_MASK)
        } else {
            flags | (id & CAN_SFF_MASK)
        };
        prop_assert_eq!(Arb::from_can_id(c).map(Arb::to_can_id), Some(c));
    }

    #[test]
    fn can_id_masks_high_bits(c in any::<u32>()) {
        match Arb::from_can_id(c) {
            None => prop_assert!(c & CAN_ERR_FLAG != 0),
            Some(a) => {
                prop_assert_eq!(c & CAN_ERR_FLAG, 0);
                let width = if c & CAN_EFF_FLAG != 0 { CAN_EFF_MASK } else { CAN_SFF_MASK };
                prop_assert_eq!(a.to_can_id(), c & (CAN_EFF_FLAG | CAN_RTR_FLAG | width));
            }
        }
    }

    #[test]
    fn from_raw_accepts_exactly_valid(raw in any::<u32>()) {
        match Arb::from_raw(raw) {
            Ok(a) => {
                prop_assert!(raw_valid(raw));
                prop_assert_eq!(a.raw(), raw);
            }
            Err(e) => {
                prop_assert!(!raw_valid(raw));
                let want = if raw & 1 != 0 {
                    ArbError::UnusedBitSet
                } else {
                    ArbError::ExtBitsInStandard
                };
                prop_assert_eq!(e, want);
                prop_assert_eq!(e.errno(), 22);
            }
        }
    }

    #[test]
    fn id_range(id in any::<u32>(), rtr in any::<bool>()) {
        prop_assert_eq!(Arb::std(id, rtr).is_ok(), id <= CAN_SFF_MASK);
        prop_assert_eq!(Arb::ext(id, rtr).is_ok(), id <= CAN_EFF_MASK);
        if id > CAN_EFF_MASK {
            prop_assert_eq!(Arb::ext(id, rtr), Err(ArbError::IdOutOfRange));
        }
    }

    #[test]
    fn priority_standard(a in std_arb(Just(false)), b in std_arb(Just(false))) {
        prop_assert_eq!(a.raw() < b.raw(), a.id() < b.id());
        prop_assert_eq!(a.raw() == b.raw(), a.id() == b.id());
    }

    #[test]
    fn priority_extended(a in ext_arb(Just(false)), b in ext_arb(Just(false))) {
        prop_assert_eq!(a.raw() < b.raw(), a.id() < b.id());
        prop_assert_eq!(a.raw() == b.raw(), a.id() == b.id());
    }

    // ---- filter.rs ----

    #[test]
    fn filter_matches_reference(arb in any::<u32>(), mask in any::<u32>(), f in any_arb()) {
        let arb = arb & !1;
        let filt = ArbFilter::new(arb, mask).unwrap();
        prop_assert_eq!(filt.arb(), arb);
        prop_assert_eq!(filt.mask(), mask | 1);
        prop_assert_eq!(filt.matches(f), ref_matches(arb, mask, f.raw()));
        prop_assert_eq!(filt.is_exact(), mask | 1 == 1);
    }

    #[test]
    fn filter_rejects_unused_bit(arb in any::<u32>(), mask in any::<u32>()) {
        prop_assert_eq!(ArbFilter::new(arb | 1, mask), Err(ArbError::UnusedBitSet));
    }

    #[test]
    fn filter_all(f in any_arb()) {
        prop_assert!(ArbFilter::ALL.matches(f));
    }

    #[test]
    fn filter_exact(a in any_arb(), b in any_arb()) {
        let ex = ArbFilter::new(a.raw(), 0).unwrap();
        prop_assert!(ex.is_exact());
        prop_assert_eq!(ex, ArbFilter::exact(a));
        prop_assert!(ex.matches(a));
        prop_assert_eq!(ex.matches(b), a == b);
    }

    #[test]
    fn filter_ide_dont_care(f in any_arb(), low in 0u32..(1 << 18)) {
        let filt = ArbFilter::new(
            Arb::std(0x123, false).unwrap().raw(),
            CAN_IDE | 1 | 0x001F_FFF8,
        )
        .unwrap();
        let want = !f.is_rtr()
            && if f.is_ext() { f.id() >> 18 == 0x123 } else { f.id() == 0x123 };
        prop_assert_eq!(filt.matches(f), want);
        let hit = Arb::ext((0x123 << 18) | low, false).unwrap();
        prop_assert!(filt.matches(hit));
        prop_assert!(!filt.matches(Arb::ext((0x123 << 18) | low, true).unwrap()));
    }

    #[test]
    fn filter_rtr_dont_care(a in any_arb()) {
        let filt = ArbFilter::new(a.raw() & !CAN_RTR, CAN_RTR).unwrap();
        let data = Arb::from_raw(a.raw() & !CAN_RTR).unwrap();
        let remote = Arb::from_raw(a.raw() | CAN_RTR).unwrap();
        prop_assert!(filt.matches(data));
        prop_assert!(filt.matches(remote));
    }

    #[test]
    fn receiver_interface(
        rif in 0i32..8,
        fif in 1i32..8,
        arb in any::<u32>(),
        mask in any::<u32>(),
        f in any_arb(),
    ) {
        let filter = ArbFilter::new(arb & !1, mask).unwrap();
        let r = Receiver { ifindex: rif, filter };
        prop_assert_eq!(r.matches(fif, f), (rif == 0 || rif == fif) && filter.matches(f));
    }

    // ---- frame.rs ----

    #[test]
    fn frame_bytes_round_trip(b in any::<[u8; 16]>()) {
        let f = CanFrame::from_bytes(&b);
        prop_assert_eq!(f.to_bytes(), b);
        prop_assert_eq!(CanFrame::from_bytes(&f.to_bytes()), f);
        prop_assert_eq!(u32::from_ne_bytes([b[0], b[1], b[2], b[3]]), f.can_id);
        prop_assert!(f.dlc() <= 8);
        prop_assert_eq!(f.payload().len(), f.dlc());
    }

    #[test]
    fn frame_from_arb(a in any_arb(), dlc in 0usize..=12, data in prop::collection::vec(any::<u8>(), 0..=12)) {
        let r = CanFrame::from_arb(a, dlc, &data);
        if dlc > 8 {
            prop_assert_eq!(r, Err(FrameError::DlcTooLarge));
        } else if !a.is_rtr() && data.len() < dlc {
            prop_assert_eq!(r, Err(FrameError::DataTooShort));
        } else {
            let f = r.unwrap();
            prop_assert_eq!(f.arb(), Some(a));
            prop_assert_eq!(f.try_arb(), Ok(a));
            prop_assert_eq!(f.can_id, a.to_can_id());
            prop_assert_eq!(f.dlc(), dlc);
            prop_assert_eq!((f.pad, f.res0, f.len8_dlc), (0, 0, 0));
            let mut want = [0u8; 8];
            if !a.is_rtr() {
                want[..dlc].copy_from_slice(&data[..dlc]);
            }
            prop_assert_eq!(f.data, want);
            prop_assert_eq!(f.payload(), &want[..dlc]);
            prop_assert_eq!(CanFrame::from_bytes(&f.to_bytes()), f);
        }
    }

    // ---- sockaddr.rs ----

    #[test]
    fn sockaddr_round_trip(arb in any::<u32>(), mask in any::<u32>(), ifindex in 0u32..=i32::MAX as u32) {
        let a = SockaddrArb { family: AF_CAN, arb, mask, ifindex };
        let b = a.encode();
        prop_assert_eq!(&b[2..4], &[0u8, 0][..]);
        prop_assert_eq!(sockaddr::parse(&b), Ok(a));
    }

    #[test]
    fn sockaddr_bytes(b in any::<[u8; 16]>(), extra in prop::collection::vec(any::<u8>(), 0..16)) {
        let mut long = b.to_vec();
        long.extend_from_slice(&extra);
        let family = u16::from_ne_bytes([b[0], b[1]]);
        let ifindex = u32::from_ne_bytes([b[12], b[13], b[14], b[15]]);
        let r = sockaddr::parse(&long);
        prop_assert_eq!(r, sockaddr::parse(&b));
        if family != AF_CAN {
            prop_assert_eq!(r, Err(AddrError::BadFamily));
        } else if ifindex > i32::MAX as u32 {
            prop_assert_eq!(r, Err(AddrError::BadIfindex));
        } else {
            let mut want = b;
            want[2] = 0;
            want[3] = 0;
            prop_assert_eq!(r.unwrap().encode(), want);
        }
        for n in 0..SOCKADDR_CANARB_LEN {
            prop_assert_eq!(sockaddr::parse(&b[..n]), Err(AddrError::TooShort));
        }
    }

    #[test]
    fn sockaddr_uses(arb in any::<u32>(), mask in any::<u32>(), ifindex in 0u32..=i32::MAX as u32) {
        let a = SockaddrArb { family: AF_CAN, arb, mask, ifindex };
        match a.bind_filter() {
            Ok(r) => {
                prop_assert_eq!(arb & 1, 0);
                prop_assert_eq!(r.ifindex as u32, ifindex);
                prop_assert_eq!(r.filter, ArbFilter::new(arb, mask).unwrap());
            }
            Err(e) => {
                prop_assert_eq!(arb & 1, 1);
                prop_assert_eq!(e, AddrError::BadArb(ArbError::UnusedBitSet));
                prop_assert_eq!(e.errno(), 22);
            }
        }
        match a.dest() {
            Ok((d, i)) => {
                prop_assert_eq!(d.raw(), arb);
                prop_assert_eq!(i as u32, ifindex);
            }
            Err(e) => prop_assert_eq!(e, AddrError::BadArb(Arb::from_raw(arb).unwrap_err())),
        }
    }

    // ---- canloop.rs ----

    #[test]
    fn drop_rate(p in 0u32..=200, r in any::<u32>()) {
        match DropRate::new(p) {
            None => prop_assert!(p > 100),
            Some(d) => {
                prop_assert_eq!(u32::from(d.percent()), p);
                prop_assert_eq!(d.should_drop(r), r % 100 < p);
                if p == 0 {
                    prop_assert!(!d.should_drop(r));
                }
                if p == 100 {
                    prop_assert!(d.should_drop(r));
                }
            }
        }
    }

    #[test]
    fn dump_matches_reference(f in any_frame()) {
        let d = FrameDump::new(&f);
        prop_assert_eq!(d.as_str(), ref_dump(&f));
    }

    #[test]
    fn dump_of_built_frame(a in any_arb(), dlc in 0usize..=8, data in any::<[u8; 8]>()) {
        let f = CanFrame::from_arb(a, dlc, &data).unwrap();
        let d = FrameDump::new(&f);
        prop_assert_eq!(d.as_str(), ref_dump(&f));
        prop_assert!(d.as_str().len() <= 40);
    }
}

/// Buffers of every length around the two frame sizes, their `len` byte
/// often in the interesting range (0-80).
fn frame_buffers() -> impl Strategy<Value = Vec<u8>> {
    use proptest::collection::vec;
    let bytes = prop_oneof![
        vec(any::<u8>(), 16..=16),
        vec(any::<u8>(), 72..=72),
        vec(any::<u8>(), 0..80),
    ];
    (bytes, proptest::option::of(0u8..80)).prop_map(|(mut b, len)| {
        if let (Some(l), Some(slot)) = (len, b.get_mut(4)) {
            *slot = l;
        }
        b
    })
}

proptest! {
    /// pf_can's send check (`AnyFrame::kind`) accepts exactly the buffers
    /// `AnyFrame::parse` accepts, and names the same flavour.
    #[test]
    fn any_frame_kind_agrees_with_parse(b in frame_buffers()) {
        use rcan_core::frame::AnyFrame;
        prop_assert_eq!(AnyFrame::kind(&b), AnyFrame::parse(&b).map(|f| f.is_fd()));
    }

    /// DSOR's receive path (`AnyFrame::view`) reads the same identifier,
    /// payload and flavour as `AnyFrame::parse` builds, and refuses the
    /// same buffers.
    #[test]
    fn any_frame_view_agrees_with_parse(b in frame_buffers()) {
        use rcan_core::frame::AnyFrame;
        let parsed = AnyFrame::parse(&b);
        let want = parsed.as_ref().map(|f| {
            let payload = match f {
                AnyFrame::Classic(c) => c.payload().to_vec(),
                AnyFrame::Fd(d) => d.payload().to_vec(),
            };
            (f.can_id(), payload, f.is_fd())
        });
        let got = AnyFrame::view(&b).map(|(id, p, fd)| (id, p.to_vec(), fd));
        prop_assert_eq!(got, want);
    }
}

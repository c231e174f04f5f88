// SPDX-License-Identifier: GPL-2.0
//! The uapi headers (`include/uapi/linux/can/*.h`) are authoritative;
//! every Rust copy of their numbers and layouts must agree with them as
//! the C compiler reads them. A drift fails `cargo test --workspace`, so
//! `make check`.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use rcan_uapi_check::*;

fn values() -> BTreeMap<String, i128> {
    header_values(&repo_root()).unwrap_or_else(|e| panic!("reading the uapi headers: {e}"))
}

fn v(values: &BTreeMap<String, i128>, key: &str) -> i128 {
    *values
        .get(key)
        .unwrap_or_else(|| panic!("the headers define no {key}"))
}

/// The image of a struct of the headers with the given fields set
/// (native byte order, the rest zero), laid out by the header's offsets.
fn image(values: &BTreeMap<String, i128>, s: &str, fields: &[(&str, u64)]) -> Vec<u8> {
    let t = format!("struct {s}");
    let mut b = vec![0u8; v(values, &format!("sizeof({t})")) as usize];
    for &(f, x) in fields {
        let off = v(values, &format!("offsetof({t}, {f})")) as usize;
        let size = v(values, &format!("sizeof({t}.{f})")) as usize;
        let bytes = x.to_ne_bytes();
        let bytes = if cfg!(target_endian = "little") {
            &bytes[..size]
        } else {
            &bytes[8 - size..]
        };
        b[off..off + size].copy_from_slice(bytes);
    }
    b
}

#[test]
fn every_rust_spelling_of_a_uapi_macro_agrees_with_the_headers() {
    let root = repo_root();
    let values = values();
    let (found, bad) = check_tree(&root, &values);
    assert!(
        bad.is_empty(),
        "Rust constants that disagree with include/uapi/linux/can/*.h or mainline's <linux/can*.h>:\n{}",
        bad.iter()
            .map(|m| format!("  {m}\n"))
            .collect::<String>()
    );
    // The scan must see the copies we know of, wherever they move: the
    // kernel side's protocol numbers and ioctls, and user space's.
    let kernel = |name: &str| {
        found.iter().any(|c| {
            c.name == name
                && ["net", "rust", "drivers"]
                    .iter()
                    .any(|d| c.file.starts_with(d))
        })
    };
    let user = |name: &str| {
        found
            .iter()
            .any(|c| c.name == name && c.file.starts_with("tools"))
    };
    for name in [
        "CANPROTO_CAN",
        "CANPROTO_DSOR",
        "CANPROTO_MAX",
        "SIOCRCANSJA1000GET",
        "SIOCRCANSJA1000SET",
        "SIOCRCANI82527GET",
        "SIOCRCANI82527ANSWER",
    ] {
        assert!(
            kernel(name),
            "no kernel-side Rust definition of {name} found"
        );
        assert!(user(name), "no user-space Rust definition of {name} found");
    }
    // Mainline's J1939 uapi, macros and enum constants, on the kernel
    // side (the module's core; user space uses libc's or its own).
    for name in [
        "CAN_J1939",
        "SOL_CAN_J1939",
        "J1939_NO_PGN",
        "J1939_FILTER_MAX",
        "SO_J1939_FILTER",
        "SCM_J1939_ERRQUEUE",
        "J1939_NLA_DEST_ADDR",
        "J1939_EE_INFO_RX_ABORT",
    ] {
        assert!(
            kernel(name),
            "no kernel-side Rust definition of {name} found"
        );
    }
}

#[test]
fn a_drifted_constant_fails_the_check() {
    let values = values();
    let dir = std::env::temp_dir().join(format!("rcan-uapi-drift.{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(dir.join("net/can")).unwrap();
    // Built from pieces so that the scan of the real tree, which skips
    // this crate anyway, could never take these for definitions.
    let c = "const";
    fs::write(
        dir.join("net/can/drift.rs"),
        format!(
            "pub(crate) {c} CANPROTO_DSOR: i32 = 18;\n\
             {c} CAN_IDE: u32 = 1 << 2; // agrees\n\
             pub {c} SIOCRCANSJA1000SET: u32 =\n    SIOCDEVPRIVATE + 1;\n\
             {c} CAN_RTR: u32 = two();\n\
             {c} NOT_A_UAPI_NAME: u32 = 7;\n"
        ),
    )
    .unwrap();
    let (found, bad) = check_tree(&dir, &values);
    let _ = fs::remove_dir_all(&dir);
    let names: Vec<&str> = found.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(
        names,
        ["CANPROTO_DSOR", "CAN_IDE", "SIOCRCANSJA1000SET", "CAN_RTR"]
    );
    let bad: Vec<(String, usize, bool)> = bad
        .iter()
        .map(|m| (m.at.name.clone(), m.at.line, m.rust.is_ok()))
        .collect();
    assert_eq!(
        bad,
        [
            ("CANPROTO_DSOR".to_string(), 1, true),
            ("CAN_RTR".to_string(), 5, false)
        ]
    );
}

#[test]
fn rcan_uapi_agrees_with_the_headers_by_value() {
    use rcan_uapi as u;
    let values = values();
    let same = |name: &str, x: i128| assert_eq!(x, v(&values, name), "rcan_uapi::{name}");
    same("AF_CAN", u::AF_CAN.into());
    same("PF_CAN", u::PF_CAN.into());
    same("CANPROTO_CAN", u::CANPROTO_CAN.into());
    same("CANPROTO_DSOR", u::CANPROTO_DSOR.into());
    same("CANPROTO_MAX", u::CANPROTO_MAX.into());
    same("CAN_IDE", u::CAN_IDE.into());
    same("CAN_RTR", u::CAN_RTR.into());
    same("CAN_ARB_UNUSED", u::CAN_ARB_UNUSED.into());
    same("CAN_MASK_EXACT", u::CAN_MASK_EXACT.into());
    same("CAN_MASK_ANY", u::CAN_MASK_ANY.into());
    same("CAN_ARB_MAX_DLC", u::CAN_ARB_MAX_DLC as i128);
    same("DSOR_NODE_ANY", u::dsor::DSOR_NODE_ANY.into());
    same("DSOR_ID_ANY", u::dsor::DSOR_ID_ANY.into());
    same("DSOR_MAX_LEN", u::dsor::DSOR_MAX_LEN as i128);
    same("SIOCDEVPRIVATE", u::SIOCDEVPRIVATE.into());

    // struct sockaddr_canarb: size, alignment, every field's place.
    same(
        "sizeof(struct sockaddr_canarb)",
        u::SOCKADDR_CANARB_LEN as i128,
    );
    same(
        "sizeof(struct sockaddr_canarb)",
        std::mem::size_of::<u::SockaddrCanArb>() as i128,
    );
    same(
        "alignof(struct sockaddr_canarb)",
        std::mem::align_of::<u::SockaddrCanArb>() as i128,
    );
    use std::mem::offset_of;
    for (f, off) in [
        ("family", offset_of!(u::SockaddrCanArb, family)),
        ("arb", offset_of!(u::SockaddrCanArb, arb)),
        ("mask", offset_of!(u::SockaddrCanArb, mask)),
        ("ifindex", offset_of!(u::SockaddrCanArb, ifindex)),
    ] {
        same(
            &format!("offsetof(struct sockaddr_canarb, {f})"),
            off as i128,
        );
    }
    let a = u::SockaddrCanArb::new(0x1234_5678, 0x9abc_def1, 7);
    let want = image(
        &values,
        "sockaddr_canarb",
        &[
            ("family", 29),
            ("arb", 0x1234_5678),
            ("mask", 0x9abc_def1),
            ("ifindex", 7),
        ],
    );
    assert_eq!(a.to_bytes().to_vec(), want);

    // The DSOR addresses, as rcan_uapi writes them.
    let segm = u::dsor::DsorAddr::Segm {
        prio: 0x11,
        node: 0x22,
        id: 0x3344_5566,
    };
    let want = image(
        &values,
        "sockaddr_cansegm",
        &[
            ("family", 29),
            ("priority", 0x11),
            ("node", 0x22),
            ("id", 0x3344_5566),
        ],
    );
    assert_eq!(segm.to_bytes(), want);
    assert_eq!(u::dsor::DsorAddr::from_bytes(&want), Some(segm));
    let port = u::dsor::DsorAddr::Port {
        prio: 0x11,
        port: 0x2233,
    };
    let want = image(
        &values,
        "sockaddr_canport",
        &[("family", 29), ("port", 0x2233), ("priority", 0x11)],
    );
    assert_eq!(port.to_bytes(), want);
    assert_eq!(u::dsor::DsorAddr::from_bytes(&want), Some(port));

    // The function-like macros.
    let c = c_eval(
        &repo_root(),
        &[
            "CAN_ARB_STD(0xfff)",
            "CAN_ARB_EXT(0xfffffffful)",
            "CAN_ARB_STD_ID(CAN_ARB_STD(0x5a5))",
            "CAN_ARB_EXT_ID(CAN_ARB_EXT(0x1abcdef0))",
            "DSOR_PORT(0x85, 0x07)",
            "DSOR_PORT_NODE(0x1234)",
            "DSOR_PORT_SUB(0x1234)",
        ],
    )
    .unwrap();
    assert_eq!(c["CAN_ARB_STD(0xfff)"], u::arb_std(0xfff, false).into());
    assert_eq!(
        c["CAN_ARB_EXT(0xfffffffful)"],
        u::arb_ext(0xffff_ffff, false).into()
    );
    assert_eq!(
        c["CAN_ARB_STD_ID(CAN_ARB_STD(0x5a5))"],
        u::arb_id(u::arb_std(0x5a5, false)).into()
    );
    assert_eq!(
        c["CAN_ARB_EXT_ID(CAN_ARB_EXT(0x1abcdef0))"],
        u::arb_id(u::arb_ext(0x1abc_def0, false)).into()
    );
    assert_eq!(
        c["DSOR_PORT(0x85, 0x07)"],
        u::dsor::dsor_port(0x85, 0x07).into()
    );
    assert_eq!(c["DSOR_PORT_NODE(0x1234)"], 0x12);
    assert_eq!(c["DSOR_PORT_SUB(0x1234)"], 0x34);
}

#[test]
fn rcan_core_agrees_with_the_headers_by_value() {
    use rcan_core::{arb, dsor_addr, dsor_wire, sockaddr};
    let values = values();
    let same = |name: &str, x: i128| assert_eq!(x, v(&values, name), "rcan_core: {name}");
    same("CAN_IDE", arb::CAN_IDE.into());
    same("CAN_RTR", arb::CAN_RTR.into());
    same("CAN_ARB_UNUSED", arb::ARB_UNUSED.into());
    same("CAN_ARB_MAX_DLC", arb::MAX_DLC as i128);
    same("AF_CAN", sockaddr::AF_CAN.into());
    same(
        "sizeof(struct sockaddr_canarb)",
        sockaddr::SOCKADDR_CANARB_LEN as i128,
    );
    same("DSOR_NODE_ANY", dsor_addr::DSOR_NODE_ANY.into());
    same("DSOR_ID_ANY", dsor_addr::DSOR_ID_ANY.into());
    same("DSOR_NODE_MAX", dsor_addr::DSOR_NODE_MAX.into());
    same("DSOR_MAX_LEN", dsor_wire::MAX_LEN as i128);
    same(
        "sizeof(struct sockaddr_cansegm)",
        dsor_addr::SOCKADDR_CANSEGM_LEN as i128,
    );
    same(
        "sizeof(struct sockaddr_canport)",
        dsor_addr::SOCKADDR_CANPORT_LEN as i128,
    );

    // What the kernel reads from and writes to user space.
    let want = image(
        &values,
        "sockaddr_canarb",
        &[
            ("family", 29),
            ("arb", 0x1234_5678),
            ("mask", 0x9abc_def1),
            ("ifindex", 7),
        ],
    );
    let a = sockaddr::parse(&want).expect("a valid sockaddr_canarb");
    assert_eq!(
        (a.family, a.arb, a.mask, a.ifindex),
        (29, 0x1234_5678, 0x9abc_def1, 7)
    );
    assert_eq!(a.encode().to_vec(), want);

    let segm = dsor_addr::DsorAddr::Segm {
        prio: 0x11,
        node: 0x22,
        id: 0x3344_5566,
    };
    let want = image(
        &values,
        "sockaddr_cansegm",
        &[
            ("family", 29),
            ("priority", 0x11),
            ("node", 0x22),
            ("id", 0x3344_5566),
        ],
    );
    let (b, n) = segm.encode();
    assert_eq!(b[..n].to_vec(), want);
    assert_eq!(dsor_addr::DsorAddr::parse(&want), Ok(segm));
    let port = dsor_addr::DsorAddr::Port {
        prio: 0x11,
        port: 0x2233,
    };
    let want = image(
        &values,
        "sockaddr_canport",
        &[("family", 29), ("port", 0x2233), ("priority", 0x11)],
    );
    let (b, n) = port.encode();
    assert_eq!(b[..n].to_vec(), want);
    assert_eq!(dsor_addr::DsorAddr::parse(&want), Ok(port));

    let c = c_eval(
        &repo_root(),
        &[
            "DSOR_PORT(0x55, 0xaa)",
            "DSOR_PORT_NODE(0x55aa)",
            "DSOR_PORT_SUB(0x55aa)",
        ],
    )
    .unwrap();
    assert_eq!(
        c["DSOR_PORT(0x55, 0xaa)"],
        dsor_addr::make_port(0x55, 0xaa).into()
    );
    assert_eq!(
        c["DSOR_PORT_NODE(0x55aa)"],
        dsor_addr::port_node(0x55aa).into()
    );
    assert_eq!(
        c["DSOR_PORT_SUB(0x55aa)"],
        dsor_addr::port_sub(0x55aa).into()
    );
}

#[test]
fn the_compiler_reads_the_headers_in_this_tree() {
    // The values come from this tree's headers, not from an installed
    // copy: a header changed here changes what the check expects.
    let root = repo_root();
    let dir = std::env::temp_dir().join(format!("rcan-uapi-root.{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    let hdr = dir.join("include/uapi/linux/can");
    fs::create_dir_all(&hdr).unwrap();
    for h in rcan_headers(&root) {
        let text = fs::read_to_string(&h).unwrap();
        let text = text.replace("#define CANPROTO_DSOR\t17", "#define CANPROTO_DSOR\t18");
        fs::write(hdr.join(h.file_name().unwrap()), text).unwrap();
    }
    let changed = header_values(Path::new(&dir));
    let _ = fs::remove_dir_all(&dir);
    let changed = changed.unwrap();
    assert_eq!(changed["CANPROTO_DSOR"], 18);
    assert_eq!(values()["CANPROTO_DSOR"], 17);
}

#[test]
fn driver_ioctl_structs_agree_with_the_headers() {
    use rcan_chips::{i82527, sja1000};
    use rcan_core::frame::{CanFrame, CAN_FRAME_LEN};
    let values = values();
    let same = |name: &str, x: i128| assert_eq!(x, v(&values, name), "rcan_core: {name}");

    // struct rcan_sja1000_setup (driver and sja1000config).
    same(
        "sizeof(struct rcan_sja1000_setup)",
        sja1000::SETUP_LEN as i128,
    );
    let s = sja1000::Setup {
        btr0: 0x11,
        btr1: 0x22,
        ocr: 0x33,
        cdr: 0x44,
        state: 2,
        rxerr: 0x55,
        txerr: 0x66,
        restarts: 0x7788_99aa,
        xtal_hz: 16_000_000,
    };
    let want = image(
        &values,
        "rcan_sja1000_setup",
        &[
            ("btr0", 0x11),
            ("btr1", 0x22),
            ("ocr", 0x33),
            ("cdr", 0x44),
            ("state", 2),
            ("rxerr", 0x55),
            ("txerr", 0x66),
            ("restarts", 0x7788_99aa),
            ("xtal_hz", 16_000_000),
        ],
    );
    assert_eq!(s.to_bytes().to_vec(), want);
    assert_eq!(sja1000::Setup::from_bytes(&want.try_into().unwrap()), s);

    // struct rcan_i82527_setup (driver and i82527config).
    same(
        "sizeof(struct rcan_i82527_setup)",
        i82527::SETUP_LEN as i128,
    );
    let s = i82527::Setup {
        cpu_if: 0x41,
        clkout: 0x32,
        bus_cfg: 0x5e,
        bt0: 0x01,
        bt1: 0x1c,
        state: 3,
        std_answers_exact: 1,
        restarts: 0x0102_0304,
    };
    let want = image(
        &values,
        "rcan_i82527_setup",
        &[
            ("cpu_if", 0x41),
            ("clkout", 0x32),
            ("bus_cfg", 0x5e),
            ("bt0", 0x01),
            ("bt1", 0x1c),
            ("state", 3),
            ("std_answers_exact", 1),
            ("restarts", 0x0102_0304),
        ],
    );
    assert_eq!(s.to_bytes().to_vec(), want);
    assert_eq!(i82527::Setup::from_bytes(&want.try_into().unwrap()), s);

    // struct rcan_i82527_answer: slot, flags, a mainline struct can_frame.
    same(
        "sizeof(struct rcan_i82527_answer)",
        i82527::ANSWER_LEN as i128,
    );
    same("RCAN_I82527_ANSWERS", i82527::ANSWERS as i128);
    let c = c_eval(
        &repo_root(),
        &[
            "sizeof(struct can_frame)",
            "offsetof(struct can_frame, can_id)",
            "offsetof(struct can_frame, len)",
            "offsetof(struct can_frame, data)",
        ],
    )
    .unwrap();
    assert_eq!(c["sizeof(struct can_frame)"], CAN_FRAME_LEN as i128);
    let f = CanFrame {
        can_id: 0x123,
        len: 3,
        data: [0xa1, 0xb2, 0xc3, 0, 0, 0, 0, 0],
        ..CanFrame::default()
    };
    let fb = f.to_bytes();
    assert_eq!(
        fb[c["offsetof(struct can_frame, can_id)"] as usize..][..4],
        0x123u32.to_ne_bytes()
    );
    assert_eq!(fb[c["offsetof(struct can_frame, len)"] as usize], 3);
    assert_eq!(
        fb[c["offsetof(struct can_frame, data)"] as usize..][..3],
        [0xa1, 0xb2, 0xc3]
    );
    let mut want = image(
        &values,
        "rcan_i82527_answer",
        &[
            ("slot", 5),
            ("flags", v(&values, "RCAN_I82527_PUBLISH") as u64),
        ],
    );
    let off = v(&values, "offsetof(struct rcan_i82527_answer, frame)") as usize;
    want[off..off + CAN_FRAME_LEN].copy_from_slice(&fb);
    let a = i82527::AnswerReq {
        slot: 5,
        frame: Some(f),
    };
    assert_eq!(a.to_bytes().to_vec(), want);
    assert_eq!(i82527::AnswerReq::from_bytes(&want.try_into().unwrap()), a);
}

#[test]
fn canfd_frame_agrees_with_mainline() {
    use rcan_core::frame::{
        can_fd_dlc2len, CanFdFrame, CANFD_BRS, CANFD_ESI, CANFD_FDF, CANFD_MAX_DLC, CANFD_MAX_DLEN,
        CANFD_MTU, CAN_MTU,
    };
    let vals = values();
    assert_eq!(v(&vals, "CANFD_MTU"), CANFD_MTU as i128);
    assert_eq!(v(&vals, "CAN_MTU"), CAN_MTU as i128);
    assert_eq!(v(&vals, "CANFD_MAX_DLEN"), CANFD_MAX_DLEN as i128);
    assert_eq!(v(&vals, "CANFD_MAX_DLC"), i128::from(CANFD_MAX_DLC));
    assert_eq!(v(&vals, "CANFD_BRS"), i128::from(CANFD_BRS));
    assert_eq!(v(&vals, "CANFD_ESI"), i128::from(CANFD_ESI));
    assert_eq!(v(&vals, "CANFD_FDF"), i128::from(CANFD_FDF));
    assert_eq!(can_fd_dlc2len(CANFD_MAX_DLC) as usize, CANFD_MAX_DLEN);
    let c = c_eval(
        &repo_root(),
        &[
            "sizeof(struct canfd_frame)",
            "offsetof(struct canfd_frame, can_id)",
            "offsetof(struct canfd_frame, len)",
            "offsetof(struct canfd_frame, flags)",
            "offsetof(struct canfd_frame, data)",
        ],
    )
    .unwrap();
    assert_eq!(c["sizeof(struct canfd_frame)"], CANFD_MTU as i128);
    let mut f = CanFdFrame {
        can_id: 0x123,
        len: 12,
        flags: CANFD_BRS,
        ..CanFdFrame::default()
    };
    f.data[11] = 0x5a;
    let b = f.to_bytes();
    assert_eq!(
        b[c["offsetof(struct canfd_frame, can_id)"] as usize..][..4],
        0x123u32.to_ne_bytes()
    );
    assert_eq!(b[c["offsetof(struct canfd_frame, len)"] as usize], 12);
    assert_eq!(
        b[c["offsetof(struct canfd_frame, flags)"] as usize],
        CANFD_BRS
    );
    assert_eq!(
        b[c["offsetof(struct canfd_frame, data)"] as usize + 11],
        0x5a
    );
}

#[test]
fn rcan_core_j1939_agrees_with_mainline() {
    use rcan_core::j1939 as j;
    let values = values();
    let same = |name: &str, x: i128| assert_eq!(x, v(&values, name), "rcan_core::j1939::{name}");
    // Macros of <linux/can.h> and <linux/can/j1939.h>.
    same("CAN_J1939", j::CAN_J1939.into());
    same("SOL_CAN_J1939", j::SOL_CAN_J1939.into());
    same("J1939_MAX_UNICAST_ADDR", j::J1939_MAX_UNICAST_ADDR.into());
    same("J1939_IDLE_ADDR", j::J1939_IDLE_ADDR.into());
    same("J1939_NO_ADDR", j::J1939_NO_ADDR.into());
    same("J1939_NO_NAME", j::J1939_NO_NAME.into());
    same("J1939_PGN_REQUEST", j::J1939_PGN_REQUEST.into());
    same(
        "J1939_PGN_ADDRESS_CLAIMED",
        j::J1939_PGN_ADDRESS_CLAIMED.into(),
    );
    same(
        "J1939_PGN_ADDRESS_COMMANDED",
        j::J1939_PGN_ADDRESS_COMMANDED.into(),
    );
    same("J1939_PGN_PDU1_MAX", j::J1939_PGN_PDU1_MAX.into());
    same("J1939_PGN_MAX", j::J1939_PGN_MAX.into());
    same("J1939_NO_PGN", j::J1939_NO_PGN.into());
    same("J1939_FILTER_MAX", j::J1939_FILTER_MAX as i128);
    // Its enum constants (read through enum_constants).
    for (name, x) in [
        ("SO_J1939_FILTER", j::SO_J1939_FILTER),
        ("SO_J1939_PROMISC", j::SO_J1939_PROMISC),
        ("SO_J1939_SEND_PRIO", j::SO_J1939_SEND_PRIO),
        ("SO_J1939_ERRQUEUE", j::SO_J1939_ERRQUEUE),
        ("SCM_J1939_DEST_ADDR", j::SCM_J1939_DEST_ADDR),
        ("SCM_J1939_DEST_NAME", j::SCM_J1939_DEST_NAME),
        ("SCM_J1939_PRIO", j::SCM_J1939_PRIO),
        ("SCM_J1939_ERRQUEUE", j::SCM_J1939_ERRQUEUE),
        ("J1939_NLA_PAD", j::J1939_NLA_PAD),
        ("J1939_NLA_BYTES_ACKED", j::J1939_NLA_BYTES_ACKED),
        ("J1939_NLA_TOTAL_SIZE", j::J1939_NLA_TOTAL_SIZE),
        ("J1939_NLA_PGN", j::J1939_NLA_PGN),
        ("J1939_NLA_SRC_NAME", j::J1939_NLA_SRC_NAME),
        ("J1939_NLA_DEST_NAME", j::J1939_NLA_DEST_NAME),
        ("J1939_NLA_SRC_ADDR", j::J1939_NLA_SRC_ADDR),
        ("J1939_NLA_DEST_ADDR", j::J1939_NLA_DEST_ADDR),
        ("J1939_EE_INFO_NONE", j::J1939_EE_INFO_NONE),
        ("J1939_EE_INFO_TX_ABORT", j::J1939_EE_INFO_TX_ABORT),
        ("J1939_EE_INFO_RX_RTS", j::J1939_EE_INFO_RX_RTS),
        ("J1939_EE_INFO_RX_DPO", j::J1939_EE_INFO_RX_DPO),
        ("J1939_EE_INFO_RX_ABORT", j::J1939_EE_INFO_RX_ABORT),
    ] {
        same(name, x.into());
    }
    // Every enum constant of the header is among the values (a new one
    // in a later header would show up here).
    let n = values
        .keys()
        .filter(|k| {
            ["SO_J1939_", "SCM_J1939_", "J1939_NLA_", "J1939_EE_INFO_"]
                .iter()
                .any(|p| k.starts_with(p))
        })
        .count();
    assert_eq!(n, 21);

    // Layouts: struct j1939_filter and sockaddr_can's j1939 part.
    let c = c_eval(
        &repo_root(),
        &[
            "sizeof(struct j1939_filter)",
            "offsetof(struct j1939_filter, name)",
            "offsetof(struct j1939_filter, name_mask)",
            "offsetof(struct j1939_filter, pgn)",
            "offsetof(struct j1939_filter, pgn_mask)",
            "offsetof(struct j1939_filter, addr)",
            "offsetof(struct j1939_filter, addr_mask)",
            "offsetof(struct sockaddr_can, can_ifindex)",
            "offsetof(struct sockaddr_can, can_addr.j1939.name)",
            "offsetof(struct sockaddr_can, can_addr.j1939.pgn)",
            "offsetof(struct sockaddr_can, can_addr.j1939.addr)",
            "offsetof(struct sockaddr_can, can_addr.j1939) + sizeof(((struct sockaddr_can *)0)->can_addr.j1939)",
        ],
    )
    .unwrap();
    assert_eq!(c["sizeof(struct j1939_filter)"], j::Filter::SIZE as i128);
    let f = j::Filter {
        name: 0x0102_0304_0506_0708,
        name_mask: 0x1112_1314_1516_1718,
        pgn: 0x2122_2324,
        pgn_mask: 0x3132_3334,
        addr: 0x41,
        addr_mask: 0x51,
    };
    let mut want = vec![0u8; j::Filter::SIZE];
    let put = |w: &mut Vec<u8>, field: &str, bytes: &[u8]| {
        let off = c[&format!("offsetof(struct j1939_filter, {field})")] as usize;
        w[off..off + bytes.len()].copy_from_slice(bytes);
    };
    put(&mut want, "name", &f.name.to_ne_bytes());
    put(&mut want, "name_mask", &f.name_mask.to_ne_bytes());
    put(&mut want, "pgn", &f.pgn.to_ne_bytes());
    put(&mut want, "pgn_mask", &f.pgn_mask.to_ne_bytes());
    put(&mut want, "addr", &[f.addr]);
    put(&mut want, "addr_mask", &[f.addr_mask]);
    assert_eq!(f.to_bytes().to_vec(), want);
    assert_eq!(
        c["offsetof(struct sockaddr_can, can_addr.j1939) + sizeof(((struct sockaddr_can *)0)->can_addr.j1939)"],
        j::SOCKADDR_J1939_LEN as i128
    );
    let a = j::SockAddr {
        ifindex: 0x0a0b_0c0d,
        name: 0x1122_3344_5566_7788,
        pgn: 0x0001_2300,
        addr: 0x99,
    };
    let mut want = vec![0u8; j::SOCKADDR_J1939_LEN];
    want[..2].copy_from_slice(&29u16.to_ne_bytes());
    let at = |k: &str| c[&format!("offsetof(struct sockaddr_can, {k})")] as usize;
    want[at("can_ifindex")..][..4].copy_from_slice(&a.ifindex.to_ne_bytes());
    want[at("can_addr.j1939.name")..][..8].copy_from_slice(&a.name.to_ne_bytes());
    want[at("can_addr.j1939.pgn")..][..4].copy_from_slice(&a.pgn.to_ne_bytes());
    want[at("can_addr.j1939.addr")] = a.addr;
    assert_eq!(a.to_bytes().to_vec(), want);
    assert_eq!(j::SockAddr::parse(&want), Ok(a));
}

// SPDX-License-Identifier: GPL-2.0
//! `rcan-mangen DIR` writes a man page and three completions per tool,
//! and the pages carry the tools' own options.

use std::process::Command;

#[test]
fn pages_and_completions() {
    let dir = std::env::temp_dir().join(format!("rcan-mangen-test-{}", std::process::id()));
    let st = Command::new(env!("CARGO_BIN_EXE_rcan-mangen"))
        .arg(&dir)
        .status()
        .unwrap();
    assert!(st.success());
    for (tool, option) in [
        ("sja1000config", "IFACE"),
        ("i82527config", "withdraw"),
        ("dsor-peer", "ack\\-timeout\\-ms"),
        ("canarb-demo", "IFACE"),
        ("canzlogd", "flush\\-ms"),
        ("cantcpd", "listen"),
        ("powerd", "dry\\-run"),
        ("logd", "SOURCE"),
    ] {
        let page = std::fs::read_to_string(dir.join(format!("man1/{tool}.1"))).unwrap();
        assert!(page.contains(&format!(".TH {tool}")), "{tool}.1: {page}");
        assert!(page.contains(option), "{tool}.1 lacks {option}");
        for c in [
            format!("bash/{tool}.bash"),
            format!("zsh/_{tool}"),
            format!("fish/{tool}.fish"),
        ] {
            assert!(dir.join("completions").join(&c).is_file(), "{c}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

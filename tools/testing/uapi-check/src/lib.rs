// SPDX-License-Identifier: GPL-2.0
//! The uapi headers are the one source of truth for the numbers and
//! layouts user space shares with the rcan modules; this crate checks
//! every Rust copy against them (Documentation/networking/rcan/architecture.rst,
//! "One source for the uapi").
//!
//! The headers are read by the C compiler, as a C program using them
//! would read them, not by a parser of our own: [`header_values`] asks it
//! for the value of every object-like macro that the rcan headers
//! (`include/uapi/linux/can/*.h`) and mainline's CAN headers
//! (`<linux/can.h>`, `<linux/can/raw.h>`, `<linux/can/bcm.h>`,
//! `<linux/can/error.h>`, `<linux/can/j1939.h>`) define, for the enum
//! constants of `<linux/can/j1939.h>`, and for `sizeof`, `alignof` and
//! every field's `offsetof` of the structs in the rcan headers. [`rust_consts`]
//! finds every Rust `const` in the tree whose name is one of those
//! macros, and [`check_tree`] evaluates each and compares. Constants the
//! host can link (crates `rcan-uapi` and `rcan-core`) are compared by
//! value in `tests/uapi.rs` as well, with their layouts.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};

/// The repository root (this crate is `tools/testing/uapi-check`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../..")
}

/// The rcan headers, `include/uapi/linux/can/*.h`, sorted.
pub fn rcan_headers(root: &Path) -> Vec<PathBuf> {
    let dir = root.join("include/uapi/linux/can");
    let mut v: Vec<PathBuf> = fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("readdir").path())
        .filter(|p| p.extension().is_some_and(|x| x == "h"))
        .collect();
    v.sort();
    v
}

/// Mainline's CAN headers whose macros Rust code also spells.
pub const MAINLINE_HEADERS: &[&str] = &[
    "linux/can.h",
    "linux/can/raw.h",
    "linux/can/bcm.h",
    "linux/can/error.h",
    "linux/can/j1939.h",
];

/// Mainline headers whose enum constants (not only their macros) are
/// uapi: `<linux/can/j1939.h>` gives its socket options, cmsg types,
/// netlink attributes and error-queue codes as `enum { ... }`.
pub const MAINLINE_ENUM_HEADERS: &[&str] = &["linux/can/j1939.h"];

/// Headers every other header builds on; their macros are not ours.
const BASE_HEADERS: &[&str] = &["linux/types.h", "linux/socket.h", "linux/sockios.h"];

/// Macros of the base headers that Rust code spells too.
const BASE_MACROS: &[&str] = &["SIOCDEVPRIVATE"];

/// A struct of an rcan header: its name and field names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CStruct {
    pub name: String,
    pub fields: Vec<String>,
}

/// The structs an rcan header defines (`struct NAME { ... };`), with the
/// names of their fields (the last identifier before `;` or `[`).
pub fn header_structs(text: &str) -> Vec<CStruct> {
    let text = strip_c_comments(text);
    let mut out = Vec::new();
    let mut cur: Option<CStruct> = None;
    for line in text.lines() {
        let l = line.trim();
        if let Some(c) = cur.as_mut() {
            if l.starts_with('}') {
                out.push(cur.take().expect("open struct"));
                continue;
            }
            if let Some(decl) = l.strip_suffix(';') {
                let decl = decl.split('[').next().unwrap_or(decl);
                if let Some(name) = decl.split_whitespace().last() {
                    c.fields.push(name.trim_start_matches('*').to_string());
                }
            }
        } else if let Some(rest) = l.strip_prefix("struct ") {
            if let Some(name) = rest.strip_suffix('{') {
                cur = Some(CStruct {
                    name: name.trim().to_string(),
                    fields: Vec::new(),
                });
            }
        }
    }
    out
}

fn strip_c_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("/*") {
        out.push_str(&rest[..i]);
        match rest[i..].find("*/") {
            Some(j) => rest = &rest[i + j + 2..],
            None => return out,
        }
    }
    out.push_str(rest);
    out
}

static SEQ: AtomicU32 = AtomicU32::new(0);

/// What [`run_c`] does with a program.
#[derive(Clone, Copy, PartialEq, Eq)]
enum CMode {
    /// The preprocessor's macro list (`-dM -E`).
    Macros,
    /// The preprocessed text (`-E`), with its line markers.
    Preprocess,
    /// Build and run the program; its output.
    Run,
}

/// Runs the C compiler (`$CC`, else `cc`) with `-I include/uapi` on
/// `program` in `mode` and returns what it printed (see [`CMode`]).
fn run_c_mode(root: &Path, program: &str, mode: CMode) -> Result<String, String> {
    let dump_macros = mode != CMode::Run;
    let dir = std::env::temp_dir().join(format!(
        "rcan-uapi-check.{}.{}",
        std::process::id(),
        SEQ.fetch_add(1, Ordering::Relaxed)
    ));
    fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let src = dir.join("uapi.c");
    let exe = dir.join("uapi");
    fs::write(&src, program).map_err(|e| format!("{}: {e}", src.display()))?;
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".to_string());
    let mut cmd = Command::new(&cc);
    cmd.arg("-I").arg(root.join("include/uapi"));
    if mode == CMode::Macros {
        cmd.args(["-dM", "-E"]).arg(&src);
    } else if mode == CMode::Preprocess {
        cmd.arg("-E").arg(&src);
    } else {
        cmd.arg("-o").arg(&exe).arg(&src);
    }
    let out = cmd.output().map_err(|e| format!("{cc}: {e}"))?;
    if !out.status.success() {
        let _ = fs::remove_dir_all(&dir);
        return Err(format!(
            "{cc} failed on the uapi headers:\n{}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let text = if dump_macros {
        String::from_utf8_lossy(&out.stdout).into_owned()
    } else {
        let run = Command::new(&exe)
            .output()
            .map_err(|e| format!("{}: {e}", exe.display()))?;
        if !run.status.success() {
            let _ = fs::remove_dir_all(&dir);
            return Err(format!("{} failed: {}", exe.display(), run.status));
        }
        String::from_utf8_lossy(&run.stdout).into_owned()
    };
    let _ = fs::remove_dir_all(&dir);
    Ok(text)
}

/// [`run_c_mode`]: with `dump_macros` the macro list, else the output of
/// the program.
fn run_c(root: &Path, program: &str, dump_macros: bool) -> Result<String, String> {
    run_c_mode(
        root,
        program,
        if dump_macros {
            CMode::Macros
        } else {
            CMode::Run
        },
    )
}

/// The enumerators of every `enum { ... }` that the preprocessed text
/// `pp` (with `# LINE "FILE"` markers) takes from a file whose path ends
/// in one of `headers`, in order.
pub fn enum_constants(pp: &str, headers: &[&str]) -> Vec<String> {
    let mut text = String::new();
    let mut inside = false;
    for line in pp.lines() {
        if let Some(marker) = line.strip_prefix("# ") {
            let file = marker.split('"').nth(1).unwrap_or("");
            inside = headers.iter().any(|h| file.ends_with(&format!("/{h}")));
            continue;
        }
        if inside {
            text.push_str(line);
            text.push('\n');
        }
    }
    let mut out = Vec::new();
    let mut rest = text.as_str();
    while let Some(i) = rest.find("enum") {
        let after = &rest[i + 4..];
        // A whole word, followed by an optional tag and a body.
        let word_start = i == 0
            || !rest[..i]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        let open = after.find('{');
        let semi = after.find(';');
        match (word_start, open) {
            (true, Some(o)) if semi.is_none_or(|s| o < s) => {
                let Some(close) = after[o..].find('}') else {
                    break;
                };
                for item in after[o + 1..o + close].split(',') {
                    let name: String = item
                        .trim()
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if !name.is_empty() {
                        out.push(name);
                    }
                }
                rest = &after[o + close..];
            }
            _ => rest = after,
        }
    }
    out
}

fn includes(headers: &[String]) -> String {
    headers
        .iter()
        .map(|h| format!("#include <{h}>\n"))
        .collect()
}

/// Object-like macros with a value in a `-dM -E` dump.
fn object_macros(dump: &str) -> BTreeSet<String> {
    dump.lines()
        .filter_map(|l| l.strip_prefix("#define "))
        .filter_map(|l| {
            let (name, value) = l.split_once(' ')?;
            (!name.contains('(') && !value.trim().is_empty()).then(|| name.to_string())
        })
        .collect()
}

/// Every header the checks include: the base headers, mainline's CAN
/// headers and the rcan headers (as `<linux/can/NAME.h>`).
fn all_headers(root: &Path) -> Vec<String> {
    let mut all: Vec<String> = BASE_HEADERS.iter().map(|s| s.to_string()).collect();
    all.extend(MAINLINE_HEADERS.iter().map(|s| s.to_string()));
    all.extend(rcan_headers(root).iter().map(|p| {
        format!(
            "linux/can/{}",
            p.file_name().expect("file name").to_string_lossy()
        )
    }));
    all
}

/// Evaluates C integer expressions `(key, expression)` in a program that
/// includes every header of [`all_headers`]; returns the values by key.
fn eval_c(root: &Path, exprs: &[(String, String)]) -> Result<BTreeMap<String, i128>, String> {
    let mut prog = String::from("#include <stdio.h>\n#include <stddef.h>\n");
    prog.push_str(&includes(&all_headers(root)));
    prog.push_str("int main(void)\n{\n");
    for (key, e) in exprs {
        prog.push_str(&format!(
            "\tprintf(\"%s\\t%lld\\n\", \"{key}\", (long long)({e}));\n"
        ));
    }
    prog.push_str("\treturn 0;\n}\n");
    let out = run_c(root, &prog, false)?;
    let mut map = BTreeMap::new();
    for l in out.lines() {
        let (k, v) = l
            .split_once('\t')
            .ok_or_else(|| format!("bad line {l:?}"))?;
        let v: i128 = v.parse().map_err(|e| format!("{l:?}: {e}"))?;
        map.insert(k.to_string(), v);
    }
    if map.len() != exprs.len() {
        return Err(format!("asked {} values, got {}", exprs.len(), map.len()));
    }
    Ok(map)
}

/// The values of C expressions over the headers (function-like macros
/// such as `CAN_ARB_STD(0x123)`), keyed by the expression.
pub fn c_eval(root: &Path, exprs: &[&str]) -> Result<BTreeMap<String, i128>, String> {
    let e: Vec<(String, String)> = exprs
        .iter()
        .map(|x| (x.to_string(), x.to_string()))
        .collect();
    eval_c(root, &e)
}

/// What the headers say: every object-like macro of the rcan and
/// mainline CAN headers (and [`BASE_MACROS`]) by name, and every enum
/// constant of [`MAINLINE_ENUM_HEADERS`]; for every struct of
/// the rcan headers `sizeof(struct S)`, `alignof(struct S)` and
/// `offsetof(struct S, f)` / `sizeof(struct S.f)` for each field `f`.
/// Values as the C compiler computes them on this host.
pub fn header_values(root: &Path) -> Result<BTreeMap<String, i128>, String> {
    let base: Vec<String> = BASE_HEADERS.iter().map(|s| s.to_string()).collect();
    let before = object_macros(&run_c(root, &includes(&base), true)?);
    let after = object_macros(&run_c(root, &includes(&all_headers(root)), true)?);
    let mut exprs: Vec<(String, String)> = after
        .difference(&before)
        .map(|m| (m.clone(), m.clone()))
        .collect();
    for m in BASE_MACROS {
        exprs.push((m.to_string(), m.to_string()));
    }
    let pp = run_c_mode(root, &includes(&all_headers(root)), CMode::Preprocess)?;
    for e in enum_constants(&pp, MAINLINE_ENUM_HEADERS) {
        if !exprs.iter().any(|(k, _)| *k == e) {
            exprs.push((e.clone(), e));
        }
    }
    for h in rcan_headers(root) {
        let text = fs::read_to_string(&h).map_err(|e| format!("{}: {e}", h.display()))?;
        for s in header_structs(&text) {
            let t = format!("struct {}", s.name);
            exprs.push((format!("sizeof({t})"), format!("sizeof({t})")));
            exprs.push((format!("alignof({t})"), format!("_Alignof({t})")));
            for f in &s.fields {
                exprs.push((format!("offsetof({t}, {f})"), format!("offsetof({t}, {f})")));
                exprs.push((
                    format!("sizeof({t}.{f})"),
                    format!("sizeof((({t} *)0)->{f})"),
                ));
            }
        }
    }
    eval_c(root, &exprs)
}

/// A Rust `const` whose name is a uapi macro.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RustConst {
    /// Relative to the scanned root.
    pub file: PathBuf,
    pub line: usize,
    pub name: String,
    /// The initialiser, as written.
    pub expr: String,
}

/// Where Rust code lives that may spell a uapi constant: kernel modules
/// (`net`, `drivers`, `rust`), user space (`tools`, `samples`) and tests.
pub const RUST_DIRS: &[&str] = &["net", "drivers", "rust", "tools", "tests", "samples"];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = fs::read_dir(dir) else { return };
    let mut entries: Vec<PathBuf> = rd.filter_map(|e| e.ok()).map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        if p.is_dir() {
            // Not build output, nor this crate (whose tests write wrong
            // constants on purpose).
            if name.as_deref() == Some("target") || p.ends_with("tools/testing/uapi-check") {
                continue;
            }
            rust_files(&p, out);
        // Not bindgen's output either: generated at build time from the
        // kernel's own headers, and not tracked.
        } else if p.extension().is_some_and(|x| x == "rs")
            && name.as_deref() != Some("bindings_generated.rs")
        {
            out.push(p);
        }
    }
}

/// Every `const NAME: TYPE = EXPR;` (any visibility, also inside `impl`
/// and `fn` bodies) in `text`: (line, name, expr).
pub fn consts_in(text: &str) -> Vec<(usize, String, String)> {
    let mut out = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    for (i, raw) in lines.iter().enumerate() {
        let code = raw.split("//").next().unwrap_or("");
        let mut words = code.split_whitespace().peekable();
        while let Some(w) = words.next() {
            if w != "const" {
                continue;
            }
            let Some(next) = words.peek() else { break };
            let name: String = next
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if name.is_empty()
                || name == "fn"
                || !name.starts_with(|c: char| c.is_ascii_uppercase())
            {
                break;
            }
            // The initialiser runs from the first '=' after the name up to
            // the ';', possibly over several lines.
            let start = code.find(&format!("const {name}")).unwrap_or(0);
            let mut rest = String::from(&code[start..]);
            let mut j = i;
            while !rest.contains(';') && j + 1 < lines.len() {
                j += 1;
                rest.push(' ');
                rest.push_str(lines[j].split("//").next().unwrap_or(""));
            }
            if let (Some(eq), Some(semi)) = (rest.find('='), rest.find(';')) {
                if eq < semi {
                    out.push((i + 1, name, rest[eq + 1..semi].trim().to_string()));
                }
            }
            break;
        }
    }
    out
}

/// Every Rust `const` under `root`'s [`RUST_DIRS`] whose name is in `names`.
pub fn rust_consts(root: &Path, names: &BTreeSet<String>) -> Vec<RustConst> {
    let mut files = Vec::new();
    for d in RUST_DIRS {
        rust_files(&root.join(d), &mut files);
    }
    let mut out = Vec::new();
    for f in files {
        let Ok(text) = fs::read_to_string(&f) else {
            continue;
        };
        for (line, name, expr) in consts_in(&text) {
            if names.contains(&name) {
                out.push(RustConst {
                    file: f.strip_prefix(root).unwrap_or(&f).to_path_buf(),
                    line,
                    name,
                    expr,
                });
            }
        }
    }
    out
}

/// Evaluates a Rust constant initialiser: integer literals (any base,
/// `_`, type suffixes), names of `values` (by their last path segment,
/// e.g. `bindings::SIOCDEVPRIVATE`), `as` casts (the value is kept: a
/// narrowing cast would show up as a mismatch), binary `* + - << >> & ^ |`
/// with Rust's precedence, parentheses. Anything else (calls, unary `!`,
/// names that are not uapi macros) is an error, never a guess.
pub fn eval_rust(expr: &str, values: &BTreeMap<String, i128>) -> Result<i128, String> {
    let toks = tokenize(expr)?;
    let mut p = Parser {
        toks: &toks,
        pos: 0,
        values,
    };
    let v = p.expr(0)?;
    if p.pos != toks.len() {
        return Err(format!(
            "cannot evaluate `{expr}`: unexpected {:?}",
            toks[p.pos]
        ));
    }
    Ok(v)
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(i128),
    Name(String),
    Op(&'static str),
    As,
}

fn tokenize(s: &str) -> Result<Vec<Tok>, String> {
    let b = s.as_bytes();
    let mut i = 0;
    let mut out = Vec::new();
    while i < b.len() {
        let c = b[i] as char;
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Tok::Num(parse_int(&s[start..i])?));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < b.len()
                && (b[i].is_ascii_alphanumeric()
                    || b[i] == b'_'
                    || (b[i] == b':' && i + 1 < b.len() && b[i + 1] == b':')
                    || (b[i] == b':' && i > 0 && b[i - 1] == b':'))
            {
                i += 1;
            }
            let word = &s[start..i];
            if word == "as" {
                out.push(Tok::As);
            } else {
                out.push(Tok::Name(
                    word.rsplit("::").next().unwrap_or(word).to_string(),
                ));
            }
        } else {
            let two = s.get(i..i + 2).unwrap_or("");
            let op: &'static str = match (two, c) {
                ("<<", _) => "<<",
                (">>", _) => ">>",
                (_, '+') => "+",
                (_, '-') => "-",
                (_, '*') => "*",
                (_, '&') => "&",
                (_, '^') => "^",
                (_, '|') => "|",
                (_, '(') => "(",
                (_, ')') => ")",
                _ => return Err(format!("cannot evaluate `{s}`: `{c}`")),
            };
            i += op.len();
            out.push(Tok::Op(op));
        }
    }
    Ok(out)
}

fn parse_int(lit: &str) -> Result<i128, String> {
    let l: String = lit.chars().filter(|&c| c != '_').collect();
    let (digits, radix) = if let Some(h) = l.strip_prefix("0x") {
        (h.to_string(), 16)
    } else if let Some(b) = l.strip_prefix("0b") {
        (b.to_string(), 2)
    } else if let Some(o) = l.strip_prefix("0o") {
        (o.to_string(), 8)
    } else {
        (l.clone(), 10)
    };
    // A type suffix (u8 .. usize, i8 .. isize) ends the digits.
    let end = digits
        .find(|c: char| c == 'u' || c == 'i' || (radix != 16 && c.is_ascii_alphabetic()))
        .unwrap_or(digits.len());
    i128::from_str_radix(&digits[..end], radix).map_err(|e| format!("`{lit}`: {e}"))
}

struct Parser<'a> {
    toks: &'a [Tok],
    pos: usize,
    values: &'a BTreeMap<String, i128>,
}

impl Parser<'_> {
    fn prec(op: &str) -> Option<u8> {
        Some(match op {
            "*" => 6,
            "+" | "-" => 5,
            "<<" | ">>" => 4,
            "&" => 3,
            "^" => 2,
            "|" => 1,
            _ => return None,
        })
    }

    fn expr(&mut self, min: u8) -> Result<i128, String> {
        let mut lhs = self.unary()?;
        while let Some(Tok::Op(op)) = self.toks.get(self.pos) {
            let Some(p) = Self::prec(op) else { break };
            if p < min {
                break;
            }
            self.pos += 1;
            let rhs = self.expr(p + 1)?;
            lhs = match *op {
                "*" => lhs * rhs,
                "+" => lhs + rhs,
                "-" => lhs - rhs,
                "<<" => lhs << rhs,
                ">>" => lhs >> rhs,
                "&" => lhs & rhs,
                "^" => lhs ^ rhs,
                _ => lhs | rhs,
            };
        }
        Ok(lhs)
    }

    fn unary(&mut self) -> Result<i128, String> {
        let v = match self.toks.get(self.pos).cloned() {
            Some(Tok::Num(n)) => {
                self.pos += 1;
                n
            }
            Some(Tok::Name(n)) => {
                self.pos += 1;
                *self
                    .values
                    .get(&n)
                    .ok_or_else(|| format!("cannot evaluate: `{n}` is not a uapi macro"))?
            }
            Some(Tok::Op("(")) => {
                self.pos += 1;
                let v = self.expr(0)?;
                if self.toks.get(self.pos) != Some(&Tok::Op(")")) {
                    return Err("cannot evaluate: missing `)`".into());
                }
                self.pos += 1;
                v
            }
            t => return Err(format!("cannot evaluate: unexpected {t:?}")),
        };
        // `as TYPE`: the type is a name; the value is kept.
        while self.toks.get(self.pos) == Some(&Tok::As) {
            match self.toks.get(self.pos + 1) {
                Some(Tok::Name(_)) => self.pos += 2,
                t => return Err(format!("cannot evaluate: `as` {t:?}")),
            }
        }
        Ok(v)
    }
}

/// One disagreement between a Rust constant and the headers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    pub at: RustConst,
    /// The Rust value, or why it could not be evaluated.
    pub rust: Result<i128, String>,
    pub header: i128,
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = &self.at;
        match &self.rust {
            Ok(v) => write!(
                f,
                "{}:{}: {} = {} ({v:#x}), the headers say {} ({:#x})",
                a.file.display(),
                a.line,
                a.name,
                a.expr,
                self.header,
                self.header
            ),
            Err(e) => write!(
                f,
                "{}:{}: {} = {}: {e}",
                a.file.display(),
                a.line,
                a.name,
                a.expr
            ),
        }
    }
}

/// Compares every Rust spelling under `root` with `values`; returns the
/// constants found and the ones that disagree (or cannot be evaluated).
pub fn check_tree(root: &Path, values: &BTreeMap<String, i128>) -> (Vec<RustConst>, Vec<Mismatch>) {
    let names: BTreeSet<String> = values
        .keys()
        .filter(|k| !k.contains('('))
        .cloned()
        .collect();
    let found = rust_consts(root, &names);
    let mut bad = Vec::new();
    for c in &found {
        let header = values[&c.name];
        let rust = eval_rust(&c.expr, values);
        if rust.as_ref().ok() != Some(&header) {
            bad.push(Mismatch {
                at: c.clone(),
                rust,
                header,
            });
        }
    }
    (found, bad)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vals() -> BTreeMap<String, i128> {
        [
            ("SIOCDEVPRIVATE", 0x89f0),
            ("SOL_CAN_BASE", 100),
            ("CAN_RAW", 1),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }

    #[test]
    fn evaluates_what_the_tree_writes() {
        let v = vals();
        for (e, want) in [
            ("0x89F0", 0x89f0),
            ("0xFFFF_FFFF", 0xffff_ffff),
            ("29", 29),
            ("8u8", 8),
            ("0b101", 5),
            ("SIOCDEVPRIVATE + 2", 0x89f2),
            ("bindings::SIOCDEVPRIVATE", 0x89f0),
            ("SOL_CAN_BASE + CAN_RAW", 101),
            ("29 as libc::c_int", 29),
            ("1 << 2 | 1", 5),
            ("(1 << 2) + 1", 5),
            ("1 + 1 << 2", 8),
            ("0x10 | 0x2 & 0x3", 0x12),
            ("10 - 2 - 3", 5),
        ] {
            assert_eq!(eval_rust(e, &v), Ok(want), "{e}");
        }
        for e in ["f()", "UNKNOWN", "1 +", "!0", "\"x\"", "(1"] {
            assert!(eval_rust(e, &v).is_err(), "{e}");
        }
    }

    #[test]
    fn finds_consts_of_every_visibility_and_shape() {
        let text = "const A: u32 = 1;\n\
                    pub const B: u32 = 2; // c\n\
                    pub(crate) const C: libc::c_ulong =\n    A + 1;\n\
                    // const D: u32 = 4;\n\
                    const fn e() {}\n\
                    impl X { const F: u8 = 6; }\n";
        let got = consts_in(text);
        let want = [
            (1, "A", "1"),
            (2, "B", "2"),
            (3, "C", "A + 1"),
            (7, "F", "6"),
        ];
        assert_eq!(got.len(), want.len(), "{got:?}");
        for (g, w) in got.iter().zip(want) {
            assert_eq!((g.0, g.1.as_str(), g.2.as_str()), w);
        }
    }

    #[test]
    fn reads_enum_constants_of_the_named_headers_only() {
        let pp = "# 1 \"/usr/include/linux/can/raw.h\" 1\n\
                  enum { CAN_RAW_FILTER = 1, };\n\
                  # 5 \"/usr/include/linux/can/j1939.h\" 1\n\
                  typedef unsigned int pgn_t;\n\
                  enum {\n SO_A = 1,\n SO_B,\n};\n\
                  enum tag { X_NONE, X_ONE = (1 << 2) };\n\
                  enum tag t;\n\
                  int enumerate;\n";
        assert_eq!(
            enum_constants(pp, &["linux/can/j1939.h"]),
            ["SO_A", "SO_B", "X_NONE", "X_ONE"]
        );
    }

    #[test]
    fn reads_struct_fields() {
        let s = header_structs(
            "/* x */\nstruct a {\n\t__u8\tb; /* c; */\n\t__u32 d[4];\n\tstruct can_frame e;\n};\n",
        );
        assert_eq!(
            s,
            [CStruct {
                name: "a".into(),
                fields: vec!["b".into(), "d".into(), "e".into()],
            }]
        );
    }
}

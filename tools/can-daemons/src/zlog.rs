// SPDX-License-Identifier: GPL-2.0
//! canzlogd's files: text lines collected in memory and written out as
//! one gzip member per flush, into files that rotate by size and age.
//!
//! Flush policy (the promise canzlogd makes, Documentation/networking/
//! rcan/canzlogd.rst): lines received since the last flush live only in
//! memory; [`ZLog::flush`] compresses them into one complete gzip member,
//! appends it to the current file with one `write(2)` and, unless fsync
//! is off, `fdatasync(2)`s the file. The daemon flushes every
//! `--flush-ms` milliseconds (and when the pending text reaches
//! [`MAX_PENDING`]), so a SIGKILL or a crash loses at most the lines of
//! the last interval, and a power loss no more either once the disk
//! honours fdatasync. Concatenated gzip members are one valid gzip
//! stream (RFC 1952 2.2), so `zcat` reads every file whole.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use flate2::write::GzEncoder;
use flate2::Compression;

/// Pending text that forces a flush before the interval is over, so a
/// burst never grows memory without bound.
pub const MAX_PENDING: usize = 1 << 20;

/// Where and how the log files are written.
#[derive(Clone, Debug)]
pub struct Config {
    /// Directory of the files.
    pub dir: PathBuf,
    /// File name prefix: files are `PREFIX-SSSSSSSSSS-NNNNNN.log.gz`
    /// (creation time in seconds since the epoch, a sequence number).
    pub prefix: String,
    /// Start a new file once the current one has this many bytes.
    pub max_size: u64,
    /// Start a new file once the current one is this old.
    pub max_age: Duration,
    /// fdatasync after every member.
    pub fsync: bool,
    /// gzip level 0-9.
    pub level: u32,
}

/// The current file and the text not yet written to it.
pub struct ZLog {
    cfg: Config,
    pending: String,
    file: Option<(File, PathBuf, Instant, u64)>,
    seq: u64,
    /// Bytes written to disk so far (all files).
    pub bytes_written: u64,
    /// Lines written to disk so far.
    pub lines_written: u64,
    pending_lines: u64,
}

impl ZLog {
    /// Creates the directory if needed; opens no file yet.
    pub fn new(cfg: Config) -> io::Result<Self> {
        fs::create_dir_all(&cfg.dir)?;
        Ok(Self {
            cfg,
            pending: String::new(),
            file: None,
            seq: 0,
            bytes_written: 0,
            lines_written: 0,
            pending_lines: 0,
        })
    }

    /// The text buffer lines are appended to; call [`ZLog::line_added`]
    /// after each whole line.
    pub fn buf(&mut self) -> &mut String {
        &mut self.pending
    }

    /// Counts a line appended to [`ZLog::buf`]; true when the pending text
    /// is large enough that the caller should flush now.
    pub fn line_added(&mut self) -> bool {
        self.pending_lines += 1;
        self.pending.len() >= MAX_PENDING
    }

    /// The current file, if one is open.
    pub fn current(&self) -> Option<&Path> {
        self.file.as_ref().map(|f| f.1.as_path())
    }

    fn open_next(&mut self) -> io::Result<()> {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .as_secs();
        loop {
            self.seq += 1;
            let path = self.cfg.dir.join(format!(
                "{}-{now:010}-{:06}.log.gz",
                self.cfg.prefix, self.seq
            ));
            match OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(f) => {
                    self.file = Some((f, path, Instant::now(), 0));
                    return Ok(());
                }
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(e),
            }
        }
    }

    /// Writes the pending lines as one gzip member (nothing if there are
    /// none), then rotates if the file reached its size or age.
    pub fn flush(&mut self) -> io::Result<()> {
        if !self.pending.is_empty() {
            if self.file.is_none() {
                self.open_next()?;
            }
            let mut z = GzEncoder::new(
                Vec::with_capacity(self.pending.len() / 4 + 64),
                Compression::new(self.cfg.level),
            );
            z.write_all(self.pending.as_bytes())?;
            let member = z.finish()?;
            let (f, _, _, size) = self.file.as_mut().expect("opened above");
            f.write_all(&member)?;
            if self.cfg.fsync {
                f.sync_data()?;
            }
            *size += member.len() as u64;
            self.bytes_written += member.len() as u64;
            self.lines_written += self.pending_lines;
            self.pending.clear();
            self.pending_lines = 0;
        }
        self.rotate_if_due()
    }

    fn rotate_if_due(&mut self) -> io::Result<()> {
        if let Some((_, _, opened, size)) = &self.file {
            if *size >= self.cfg.max_size || opened.elapsed() >= self.cfg.max_age {
                self.close()?;
            }
        }
        Ok(())
    }

    /// Flushes the pending lines and closes the current file; the next
    /// flush with lines opens a new one.
    pub fn close(&mut self) -> io::Result<()> {
        if !self.pending.is_empty() {
            // flush() ends in rotate_if_due, which may call close again:
            // by then nothing is pending.
            self.flush()?;
        }
        if let Some((f, ..)) = self.file.take() {
            if self.cfg.fsync {
                f.sync_all()?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::read::MultiGzDecoder;
    use std::io::Read;

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("zlog-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        d
    }

    fn cfg(dir: &Path, max_size: u64) -> Config {
        Config {
            dir: dir.to_path_buf(),
            prefix: "t".into(),
            max_size,
            max_age: Duration::from_secs(3600),
            fsync: false,
            level: 6,
        }
    }

    fn read_all(dir: &Path) -> (usize, String) {
        let mut names: Vec<_> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        let mut s = String::new();
        for n in &names {
            MultiGzDecoder::new(File::open(n).unwrap())
                .read_to_string(&mut s)
                .unwrap();
        }
        (names.len(), s)
    }

    #[test]
    fn members_concatenate_and_rotate() {
        let d = tmp("rot");
        let mut z = ZLog::new(cfg(&d, 200)).unwrap();
        let mut want = String::new();
        for i in 0..50 {
            let l = format!("({:010}.000000) can0 123#{i:02X}\n", i);
            z.buf().push_str(&l);
            want.push_str(&l);
            z.line_added();
            if i % 5 == 4 {
                z.flush().unwrap();
            }
        }
        z.close().unwrap();
        let (files, got) = read_all(&d);
        assert_eq!(got, want);
        assert!(files > 1, "{files} files: no rotation at 200 bytes");
        assert_eq!(z.lines_written, 50);
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn age_rotates_at_each_flush_when_due() {
        let d = tmp("age");
        let mut c = cfg(&d, 1 << 20);
        c.max_age = Duration::ZERO;
        let mut z = ZLog::new(c).unwrap();
        for i in 0..3 {
            z.buf().push_str(&format!("line {i}\n"));
            z.line_added();
            z.flush().unwrap();
        }
        z.close().unwrap();
        assert_eq!(read_all(&d), (3, "line 0\nline 1\nline 2\n".into()));
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn nothing_pending_writes_nothing() {
        let d = tmp("empty");
        let mut z = ZLog::new(cfg(&d, 1 << 20)).unwrap();
        z.flush().unwrap();
        z.close().unwrap();
        assert_eq!(read_all(&d).0, 0);
        fs::remove_dir_all(&d).unwrap();
    }
}

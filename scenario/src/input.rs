//! The one rule for every file forcecell reads (cell files, scenarios, tunings, the robot's Ethernet
//! config, traces, CAN logs): it must be a **regular file** of at most a stated size, and it is opened
//! **without blocking** (`O_NONBLOCK`), its type then checked on the opened descriptor, so a named
//! pipe, a device (`/dev/zero`), a directory or a symbolic-link loop is a one-line error, never a
//! hang or an unbounded read.

use std::fs::{File, OpenOptions};
use std::io::Read;
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::Path;

use anyhow::{Result, anyhow, bail};

/// The largest TOML file read (cell file, scenario, tuning) and the largest robot Ethernet config
/// (XML), bytes: 1 MiB, a thousand times the largest real one.
pub const MAX_CONFIG: u64 = 1 << 20;
/// The largest trace read (`plot`, `export`: an MCAP recording or a CSV), bytes: 1 GiB, about
/// ten hours of a 4 ms cycle recorded (the whole trace is read into memory).
pub const MAX_TRACE: u64 = 1 << 30;
/// The largest candump `-L` log replayed, bytes: 256 MiB (about 3 M frames).
pub const MAX_CAN_LOG: u64 = 256 << 20;

/// An I/O error's text without the "(os error N)" suffix.
pub fn os_error(e: &std::io::Error) -> String {
    let t = e.to_string();
    match t.find(" (os error") {
        Some(i) => t[..i].to_string(),
        None => t,
    }
}

/// What a path that is not a regular file is, for the error.
fn what(t: std::fs::FileType) -> &'static str {
    if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a named pipe"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "of another kind"
    }
}

/// Open `path` under the rule: without blocking, then checked to be a regular file of at most `max`
/// bytes. `kind` names the file in errors ("cell file", "trace").
pub fn open(path: &Path, kind: &str, max: u64) -> Result<File> {
    let f = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
        .map_err(|e| anyhow!("cannot read {kind} {}: {}", path.display(), os_error(&e)))?;
    let meta = f
        .metadata()
        .map_err(|e| anyhow!("cannot read {kind} {}: {}", path.display(), os_error(&e)))?;
    if !meta.is_file() {
        bail!(
            "{} is no {kind}: it is {}, not a regular file",
            path.display(),
            what(meta.file_type())
        );
    }
    if meta.len() > max {
        bail!(
            "{} is no {kind}: {} bytes, more than its limit of {max} bytes",
            path.display(),
            meta.len()
        );
    }
    Ok(f)
}

/// The bytes of `path` under the rule (see [`open`]); a file that grows past `max` while read is
/// refused too.
pub fn read(path: &Path, kind: &str, max: u64) -> Result<Vec<u8>> {
    let f = open(path, kind, max)?;
    let mut bytes = Vec::new();
    f.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| anyhow!("cannot read {kind} {}: {}", path.display(), os_error(&e)))?;
    if bytes.len() as u64 > max {
        bail!(
            "{} is no {kind}: more than its limit of {max} bytes",
            path.display()
        );
    }
    Ok(bytes)
}

/// The text of `path` under the rule (see [`open`]), which must be UTF-8.
pub fn read_text(path: &Path, kind: &str, max: u64) -> Result<String> {
    String::from_utf8(read(path, kind, max)?)
        .map_err(|_| anyhow!("{} is no {kind}: it is not UTF-8 text", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_bounded_regular_file_is_read() {
        let dir = std::env::temp_dir().join(format!("fc-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ok = dir.join("ok.toml");
        std::fs::write(&ok, "a = 1\n").unwrap();
        assert_eq!(read_text(&ok, "cell file", 100).unwrap(), "a = 1\n");
        let e = read(&ok, "cell file", 3).unwrap_err().to_string();
        assert!(e.contains("limit of 3 bytes"), "{e}");
        let e = read(Path::new("/dev/zero"), "trace", 10)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a device"), "{e}");
        let e = read(&dir, "trace", 10).unwrap_err().to_string();
        assert!(e.contains("a directory"), "{e}");
        let lp = dir.join("loop");
        let _ = std::fs::remove_file(&lp);
        std::os::unix::fs::symlink(&lp, &lp).unwrap();
        let e = read(&lp, "trace", 10).unwrap_err().to_string();
        assert!(e.starts_with("cannot read trace"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

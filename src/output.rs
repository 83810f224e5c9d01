//! The one rule for every file forcecell writes: nothing existing is touched until every option,
//! device and address has been checked; a file is written to a temporary name in its own directory and
//! renamed over the destination only when complete ([`replace`]); an output that is one of the command's
//! inputs is refused ([`refuse_input`]); the format is decided from the extension before anything is
//! opened ([`require_extension`]); a directory created for outputs is removed again, if still empty, when
//! the command fails ([`OutDir`]).

use std::fs::File;
use std::io::Write;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};

use crate::input::os_error;

/// Refuse `path` unless its extension is one of `exts` (lowercase, without the dot): the format is
/// chosen from it, before anything is opened.
pub fn require_extension(path: &Path, exts: &[&str], what: &str) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext {
        Some(e) if exts.contains(&e.as_str()) => Ok(()),
        _ => bail!(
            "{} cannot be {what}: its name must end in .{}",
            path.display(),
            exts.join(" or .")
        ),
    }
}

/// Refuse to write `output` when it is (the same file as) `input`.
pub fn refuse_input(output: &Path, input: &Path) -> Result<()> {
    let same = match (std::fs::metadata(output), std::fs::metadata(input)) {
        (Ok(o), Ok(i)) => o.dev() == i.dev() && o.ino() == i.ino(),
        _ => false,
    };
    if same || output == input {
        bail!(
            "{} is the input {}: refusing to write over it (choose another --out)",
            output.display(),
            input.display()
        );
    }
    Ok(())
}

/// The temporary name `path` is written under: in the same directory (so the rename is atomic),
/// hidden, unique to this process, with the same extension (encoders choose the format by it).
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or("out".into(), |n| n.to_string_lossy().into_owned());
    let ext = path
        .extension()
        .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!(".{name}.{}.tmp{ext}", std::process::id()))
}

/// Write `path` through `write`, which is given the temporary path to create: on success the temporary
/// file replaces `path` (rename), on failure it is removed and `path` is untouched.
pub fn replace<T>(path: &Path, write: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
    let tmp = temp_path(path);
    // An unwritable place is reported by the destination's name, before anything is produced.
    File::create(&tmp).map_err(|e| anyhow!("cannot write {}: {}", path.display(), os_error(&e)))?;
    let done = write(&tmp).and_then(|v| {
        // The data on disk before the name points at it.
        if let Ok(f) = File::open(&tmp) {
            let _ = f.sync_all();
        }
        std::fs::rename(&tmp, path)
            .map_err(|e| anyhow!("cannot write {}: {}", path.display(), os_error(&e)))?;
        Ok(v)
    });
    if done.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    done
}

/// Prove that a file can be created in `dir` (an existing directory), leaving nothing behind.
pub fn probe_writable(dir: &Path, what: &str) -> Result<()> {
    let probe = dir.join(format!(".forcecell-probe.{}", std::process::id()));
    let r = File::create(&probe).and_then(|mut f| {
        f.write_all(b"probe")?;
        f.sync_all()
    });
    let _ = std::fs::remove_file(&probe);
    r.map_err(|e| {
        anyhow!(
            "{what} {} is not writable ({})",
            dir.display(),
            os_error(&e)
        )
    })
}

/// An output directory, created with its missing parents; unless [`OutDir::keep`] is called, the
/// directories this created are removed again on drop if they are still empty.
pub struct OutDir {
    path: PathBuf,
    created: Vec<PathBuf>,
    keep: bool,
}

impl OutDir {
    /// Create `path` (and missing parents), then prove it writable.
    pub fn create(path: &Path, what: &str) -> Result<Self> {
        let mut missing = Vec::new();
        let mut p = path.to_path_buf();
        while !p.as_os_str().is_empty() && std::fs::symlink_metadata(&p).is_err() {
            missing.push(p.clone());
            if !p.pop() {
                break;
            }
        }
        let mut dir = Self {
            path: path.to_path_buf(),
            created: Vec::new(),
            keep: false,
        };
        for m in missing.iter().rev() {
            match std::fs::create_dir(m) {
                Ok(()) => dir.created.push(m.clone()),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => bail!("cannot create {what} {}: {}", path.display(), os_error(&e)),
            }
        }
        if !path.is_dir() {
            bail!("{what} {} is not a directory", path.display());
        }
        probe_writable(path, what)?;
        Ok(dir)
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The command succeeded (or wrote something worth keeping): leave the directory.
    pub fn keep(mut self) {
        self.keep = true;
    }
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if !self.keep {
            for d in self.created.iter().rev() {
                // Only an empty directory goes (remove_dir refuses any other).
                let _ = std::fs::remove_dir(d);
            }
        }
    }
}

/// Create `path`'s file for writing under a temporary name; see [`replace`].
pub fn create_temp(path: &Path) -> Result<(File, PathBuf)> {
    let tmp = temp_path(path);
    let f = File::create(&tmp).with_context(|| format!("cannot create {}", path.display()))?;
    Ok((f, tmp))
}

/// Write a CSV trace to `path` under the rule: a temporary file in the same directory, renamed over
/// `path` when complete.
pub fn write_csv(path: &Path, rows: &[crate::record::Row]) -> Result<()> {
    replace(path, |tmp| crate::record::write_csv_file(tmp, rows))
        .with_context(|| format!("cannot write {}", path.display()))
}

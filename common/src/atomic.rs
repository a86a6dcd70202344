//! The one way Parallax writes a file whole: into a temporary file beside the
//! destination (tempfile), flushed and synced, then persisted (renamed) over
//! the destination. A crash, an error or an early return never leaves a
//! half-written file under the final name, and never loses what was there
//! before. Logs that grow frame by frame (`stats.jsonl`) are streamed instead.

use anyhow::{Context, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use tempfile::NamedTempFile;

/// A file being written; it appears under its name only on [`commit`].
/// Dropping it uncommitted removes the temporary file.
///
/// [`commit`]: AtomicFile::commit
pub struct AtomicFile {
    path: PathBuf,
    out: BufWriter<NamedTempFile>,
}

impl AtomicFile {
    /// Creates the temporary file in the destination's folder.
    pub fn create(path: &Path) -> Result<Self> {
        let name = path
            .file_name()
            .with_context(|| format!("{}: not a file path", path.display()))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let mut prefix = std::ffi::OsString::from(".");
        prefix.push(name);
        prefix.push(".");
        let tmp = tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(".tmp")
            // What a plain create would give (the umask applies), not
            // tempfile's private 0600.
            .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666))
            .tempfile_in(dir)
            .with_context(|| {
                format!(
                    "{}: cannot create a file in {}",
                    path.display(),
                    dir.display()
                )
            })?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(1 << 20, tmp),
        })
    }

    /// Where the bytes go until the commit (for messages).
    pub fn temp_path(&self) -> &Path {
        self.out.get_ref().path()
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes, syncs and renames the file into place, then syncs the folder
    /// so the rename survives a power cut (where the platform allows).
    pub fn commit(self) -> Result<()> {
        let label = self.path.display().to_string();
        let tmp = self
            .out
            .into_inner()
            .map_err(|e| anyhow::anyhow!("{label}: write failed: {}", e.error()))?;
        tmp.as_file()
            .sync_all()
            .with_context(|| format!("{label}: sync failed"))?;
        tmp.persist(&self.path)
            .map_err(|e| anyhow::anyhow!("{label}: cannot rename into place: {}", e.error))?;
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.out.write_all(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Writes `bytes` to `path` atomically.
pub fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes)
        .with_context(|| format!("{}: write failed", path.display()))?;
    f.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_appears_until_commit_and_the_old_file_survives_a_drop() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write(&p, b"old").unwrap();
        {
            let mut f = AtomicFile::create(&p).unwrap();
            f.write_all(b"new, unfinished").unwrap();
            assert!(f.temp_path().exists());
        }
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "temporary file left"
        );
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"new").unwrap();
        f.commit().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        let mode = |p: &Path| {
            std::os::unix::fs::PermissionsExt::mode(&std::fs::metadata(p).unwrap().permissions())
        };
        let plain = dir.path().join("plain");
        File::create(&plain).unwrap();
        assert_eq!(mode(&p), mode(&plain), "the mode a plain create gives");
        std::fs::remove_file(&plain).unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_missing_folder_is_named() {
        let e = write(Path::new("/nonexistent-folder/x.png"), b"x").unwrap_err();
        assert!(
            format!("{e:#}").contains("/nonexistent-folder/x.png"),
            "{e:#}"
        );
    }
}

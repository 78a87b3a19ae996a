//! Reading inputs and writing outputs safely: the one way edtmap touches
//! files.
//!
//! **Inputs** are regular files only. A FIFO would block the reader
//! forever and a device (`/dev/zero`, `/dev/urandom`) never ends, so both
//! are refused before they are opened, by their metadata. Every read has a
//! size cap that is checked against the file's length before anything is
//! allocated, and again while reading (the file may grow).
//!
//! **Outputs** go through [`AtomicFile`]: the bytes are written to a new
//! temporary file beside the target, synced, and renamed over the target,
//! as git and SQLite do. A kill, a full disk or an error mid-write leaves
//! the previous file as it was; the temporary is removed on error, and the
//! temporaries of a killed run are removed by the next write of the same
//! target. A target that is a symbolic link or not a regular file is
//! refused: edtmap never writes through a link into a file the user did
//! not name.

use std::ffi::OsString;
use std::fs::{self, File, Metadata, OpenOptions};
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::IoError;

/// Largest text input read whole (configs, trajectories, intrinsics, pose
/// and query files): 256 MiB.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;

/// Largest point-cloud file read whole (PCD, PLY, KITTI `.bin`): 2 GiB,
/// a hundred million points and more, a thousand times a spinning LiDAR's
/// scan.
pub const MAX_CLOUD_BYTES: u64 = 2 << 30;

/// What kind of file system object `meta` describes, in words.
fn kind_of(meta: &Metadata) -> &'static str {
    let ft = meta.file_type();
    if ft.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// The metadata of `path` (links followed) if it is a regular file; an
/// error naming what it is otherwise.
pub fn check_regular(path: &Path) -> Result<Metadata, IoError> {
    let meta = fs::metadata(path).map_err(|e| IoError::io(path, e))?;
    if meta.is_file() {
        Ok(meta)
    } else {
        Err(IoError::NotRegular { path: path.to_path_buf(), kind: kind_of(&meta) })
    }
}

/// Opens `path` for reading after checking that it is a regular file of
/// at most `max_bytes`; returns the file and its length.
pub fn open_input(path: &Path, max_bytes: u64) -> Result<(File, u64), IoError> {
    let len = check_regular(path)?.len();
    if len > max_bytes {
        return Err(IoError::TooLarge { path: path.to_path_buf(), bytes: len, limit: max_bytes });
    }
    let file = File::open(path).map_err(|e| IoError::io(path, e))?;
    // The path may have been swapped between the check and the open.
    let meta = file.metadata().map_err(|e| IoError::io(path, e))?;
    if !meta.is_file() {
        return Err(IoError::NotRegular { path: path.to_path_buf(), kind: kind_of(&meta) });
    }
    Ok((file, meta.len()))
}

/// Files up to this size are read without asking the memory budget.
const UNBUDGETED_READ_BYTES: u64 = 64 << 20;

/// The whole of the regular file `path`, refused if longer than
/// `max_bytes` or, for a file over 64 MiB, than the memory budget
/// ([`edtmap_core::MemoryBudget::from_system`]) allows.
pub fn read_input(path: &Path, max_bytes: u64) -> Result<Vec<u8>, IoError> {
    let (file, len) = open_input(path, max_bytes)?;
    if len > UNBUDGETED_READ_BYTES {
        if let Some(limit) = edtmap_core::MemoryBudget::from_system().limit_bytes().filter(|&l| len > l) {
            return Err(IoError::OverBudget { path: path.to_path_buf(), bytes: len, limit });
        }
    }
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    // One byte past the cap tells a file that grew since the check.
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes).map_err(|e| IoError::io(path, e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(IoError::TooLarge { path: path.to_path_buf(), bytes: bytes.len() as u64, limit: max_bytes });
    }
    Ok(bytes)
}

/// The whole of the text file `path` (UTF-8, at most [`MAX_TEXT_BYTES`]).
pub fn read_text(path: &Path) -> Result<String, IoError> {
    let bytes = read_input(path, MAX_TEXT_BYTES)?;
    String::from_utf8(bytes).map_err(|e| IoError::Dataset {
        path: path.to_path_buf(),
        reason: format!("not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()),
    })
}

/// Refuses an output path that is a symbolic link or exists as something
/// other than a regular file.
pub fn check_output(path: &Path) -> Result<(), IoError> {
    let refuse = |reason: String| Err(IoError::Output { path: path.to_path_buf(), reason });
    if path.file_name().is_none() {
        return refuse("does not name a file".into());
    }
    match fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_symlink() => {
            refuse("is a symbolic link, and edtmap does not write through links: remove the link or name the file it points to".into())
        }
        Ok(meta) if !meta.is_file() => refuse(format!("exists and is {}, not a file edtmap can replace", kind_of(&meta))),
        Ok(_) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(IoError::io(path, e)),
    }
}

/// A file system identity for `path` that does not depend on how it is
/// spelled: the canonical folder joined with the file name.
fn identity(path: &Path) -> PathBuf {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let dir = fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    match path.file_name() {
        Some(name) => dir.join(name),
        None => dir,
    }
}

/// Refuses a set of outputs of which two are the same file (however
/// spelled, or hard links of one file): one would silently replace the
/// other. `paths` pairs each path with the option or argument that named it.
pub fn check_distinct_outputs(paths: &[(&str, &Path)]) -> Result<(), IoError> {
    for (i, (name_a, a)) in paths.iter().enumerate() {
        for (name_b, b) in &paths[..i] {
            if same_file(a, b) {
                return Err(IoError::Output {
                    path: a.to_path_buf(),
                    reason: format!("is named both as {name_b} and as {name_a}: each output needs its own file"),
                });
            }
        }
    }
    Ok(())
}

/// Whether `a` and `b` name the same file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    if identity(a) == identity(b) {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (fs::metadata(a), fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    false
}

/// An output file being written: bytes go to a temporary file beside the
/// target, which [`AtomicFile::commit`] syncs and renames over the target.
/// Dropped without a commit (an error, a panic), it removes the temporary
/// and leaves the target as it was.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Starts writing `path`. Fails when `path` is a link or not a regular
    /// file, or when its folder does not take a new file.
    pub fn create(path: &Path) -> Result<Self, IoError> {
        check_output(path)?;
        remove_stale_temps(path);
        let (tmp, file) = create_temp_beside(path).map_err(|e| IoError::io(path, e))?;
        Ok(AtomicFile { target: path.to_path_buf(), tmp, out: Some(BufWriter::with_capacity(1 << 20, file)) })
    }

    /// The file this will replace.
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Flushes and syncs the data and renames it over the target. On
    /// error the target is unchanged and the temporary removed.
    pub fn commit(mut self) -> Result<(), IoError> {
        let Some(out) = self.out.take() else {
            return Err(IoError::io(&self.target, io::Error::other("written after a failed commit")));
        };
        let done = out
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_all())
            .and_then(|()| fs::rename(&self.tmp, &self.target));
        if let Err(e) = done {
            // Best effort: the error that matters is the one returned.
            let _ = fs::remove_file(&self.tmp);
            return Err(IoError::io(&self.target, e));
        }
        self.tmp = PathBuf::new();
        sync_parent(&self.target);
        Ok(())
    }

    fn writer(&mut self) -> io::Result<&mut BufWriter<File>> {
        self.out.as_mut().ok_or_else(|| io::Error::other("written after commit"))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.writer()?.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.writer()?.write_all(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.writer()?.flush()
    }
}

impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.writer()?.seek(pos)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.tmp.as_os_str().is_empty() {
            self.out = None;
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `bytes` to `path` atomically (see [`AtomicFile`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Writes `path` atomically with `fill`, which writes the contents.
pub fn write_atomic_with(path: &Path, fill: impl FnOnce(&mut AtomicFile) -> io::Result<()>) -> Result<(), IoError> {
    let mut file = AtomicFile::create(path)?;
    fill(&mut file).map_err(|e| IoError::io(path, e))?;
    file.commit()
}

/// Bytes an unprivileged writer may still put on the file system that
/// holds `dir`; `None` where that cannot be told.
pub fn free_space(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let c_path = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
        let mut st = std::mem::MaybeUninit::<libc::statvfs>::uninit();
        // SAFETY: `c_path` is a NUL-terminated path that outlives the call,
        // and `st` points to writable memory of the struct's size.
        let rc = unsafe { libc::statvfs(c_path.as_ptr(), st.as_mut_ptr()) };
        if rc != 0 {
            return None;
        }
        // SAFETY: statvfs returned 0, so it filled the struct.
        let st = unsafe { st.assume_init() };
        #[allow(clippy::unnecessary_cast)] // the field types differ by platform
        Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// The temporary names of `path`: `.NAME.PID.N.tmp` in its folder.
fn temp_prefix(path: &Path) -> Option<OsString> {
    let mut prefix = OsString::from(".");
    prefix.push(path.file_name()?);
    prefix.push(".");
    Some(prefix)
}

/// Creates a new, empty temporary file in `path`'s folder, named after it.
fn create_temp_beside(path: &Path) -> io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let prefix = temp_prefix(path)
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "the path does not name a file"))?;
    let dir = parent_dir(path);
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut name = prefix.clone();
        name.push(format!("{}.{n}.tmp", std::process::id()));
        let tmp = dir.join(name);
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(file) => return Ok((tmp, file)),
            // A stale file of an earlier process with the same id: try the next name.
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && n < 100_000 => continue,
            Err(e) => return Err(e),
        }
    }
}

fn parent_dir(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Removes the temporaries of `path` left by processes that no longer run
/// (a run killed mid-write). Where process ids cannot be checked, they are
/// left alone: they are hidden files and never read.
fn remove_stale_temps(path: &Path) {
    let Some(prefix) = temp_prefix(path).and_then(|p| p.into_string().ok()) else { return };
    let Ok(entries) = fs::read_dir(parent_dir(path)) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)).and_then(|r| r.strip_suffix(".tmp"))
        else {
            continue;
        };
        let Some(pid) = rest.split('.').next().and_then(|p| p.parse::<u32>().ok()) else { continue };
        if pid != std::process::id() && !process_alive(pid) {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// Removes the temporaries this process has open in `dir` (outputs being
/// written), for a program that is about to exit mid-write: no partial
/// file is left behind, and the targets keep their previous contents.
pub fn remove_own_temporaries(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else { return };
    let own = format!(".{}.", std::process::id());
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(rest) = name.strip_prefix('.').and_then(|r| r.strip_suffix(".tmp")) else { continue };
        // `.NAME.PID.N.tmp`: the process id is the second-to-last part.
        let tail = rest.rsplit_once('.').map(|(head, n)| (head, n.bytes().all(|b| b.is_ascii_digit())));
        if let Some((head, true)) = tail {
            if format!("{head}.").ends_with(&own) {
                let _ = fs::remove_file(entry.path());
            }
        }
    }
}

/// Whether process `pid` runs; `true` where that cannot be told.
fn process_alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        true
    }
}

/// Makes the rename durable where the platform allows; a failure here does
/// not undo a write that has already replaced the file.
fn sync_parent(path: &Path) {
    #[cfg(unix)]
    if let Ok(d) = File::open(parent_dir(path)) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = path;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_target_and_no_temporary() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.txt");
        fs::write(&path, "old").expect("write");
        let err = write_atomic_with(&path, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("disk full"))
        });
        assert!(err.is_err());
        assert_eq!(fs::read_to_string(&path).expect("read"), "old");
        assert_eq!(fs::read_dir(dir.path()).expect("list").count(), 1, "the temporary is removed");
    }

    #[test]
    fn a_link_is_refused_and_its_target_kept() {
        let dir = tempfile::tempdir().expect("tempdir");
        let victim = dir.path().join("victim.txt");
        fs::write(&victim, "keep").expect("write");
        let link = dir.path().join("report.json");
        #[cfg(unix)]
        std::os::unix::fs::symlink(&victim, &link).expect("link");
        #[cfg(unix)]
        {
            let err = write_atomic(&link, b"new").expect_err("a link");
            assert!(err.to_string().contains("symbolic link"), "{err}");
            assert_eq!(fs::read_to_string(&victim).expect("read"), "keep");
        }
    }

    #[test]
    fn stale_temporaries_of_dead_processes_are_removed() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("map.edtmap");
        // Process id 0 is never a user process; u32::MAX - 1 is above any pid_max.
        let stale = dir.path().join(format!(".map.edtmap.{}.0.tmp", u32::MAX - 1));
        fs::write(&stale, "stale").expect("write");
        write_atomic(&path, b"new").expect("write");
        if cfg!(target_os = "linux") {
            assert!(!stale.exists());
        }
        assert_eq!(fs::read(&path).expect("read"), b"new");
    }

    #[test]
    fn same_file_is_found_however_spelled() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.npy");
        let b = dir.path().join(".").join("a.npy");
        let err = check_distinct_outputs(&[("OUT", &a), ("--nearest", &b)]).expect_err("same");
        assert!(err.to_string().contains("--nearest"), "{err}");
        check_distinct_outputs(&[("OUT", &a), ("--nearest", &dir.path().join("b.npy"))]).expect("distinct");
    }

    #[cfg(unix)]
    #[test]
    fn devices_and_fifos_are_refused_before_opening() {
        let err = read_input(Path::new("/dev/zero"), 1 << 20).expect_err("a device");
        assert!(err.to_string().contains("character device"), "{err}");
        let dir = tempfile::tempdir().expect("tempdir");
        let err = read_text(dir.path()).expect_err("a directory");
        assert!(err.to_string().contains("directory"), "{err}");
    }

    #[test]
    fn free_space_is_known_on_unix() {
        if cfg!(unix) {
            assert!(free_space(Path::new(".")).is_some_and(|b| b > 0));
            assert_eq!(free_space(Path::new("/no/such/folder")), None);
        }
    }

    #[test]
    fn a_file_past_the_memory_budget_is_refused_before_reading() {
        let Some(limit) = edtmap_core::MemoryBudget::from_system().limit_bytes() else { return };
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("huge.edtmap");
        let file = File::create(&path).expect("create");
        // Sparse where the file system allows: no disk is used.
        if file.set_len(limit.saturating_add(1 << 30)).is_err() {
            return;
        }
        let err = read_input(&path, u64::MAX).expect_err("past the budget");
        // Free memory moves while tests run: the budget read inside may be
        // a little above the one read here, but stays below the file.
        assert!(matches!(err, IoError::OverBudget { limit: l, .. } if l < limit.saturating_add(1 << 30)), "{err}");
    }

    #[test]
    fn a_file_over_the_cap_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("big.txt");
        fs::write(&path, [b'a'; 100]).expect("write");
        let err = read_input(&path, 99).expect_err("too big");
        assert!(matches!(err, IoError::TooLarge { bytes: 100, limit: 99, .. }), "{err}");
        assert_eq!(read_input(&path, 100).expect("fits").len(), 100);
    }
}

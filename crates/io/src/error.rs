use std::path::PathBuf;

use thiserror::Error;

/// Errors reading or writing edtmap's files. Each names the file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum IoError {
    /// A recording's frame has no pose: its time is outside the trajectory
    /// or in a gap of it. The other frames can still be read, so a caller
    /// may skip this one.
    #[error("{}: no pose at {stamp_s:.6} s: {reason}", path.display())]
    NoPose {
        /// The frame's file (depth image or point cloud).
        path: PathBuf,
        /// The frame's time, seconds.
        stamp_s: f64,
        /// Why, naming the trajectory file and the time span it covers.
        reason: String,
    },
    /// An input is not a regular file (a FIFO, a device, a directory):
    /// reading it could block or never end, so it is refused unopened.
    #[error("{}: is {kind}; edtmap reads only regular files", path.display())]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is instead, in words.
        kind: &'static str,
    },
    /// An input is longer than edtmap reads for its kind of file.
    #[error("{}: {bytes} bytes is more than the {limit} bytes read for this kind of file", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its length.
        bytes: u64,
        /// The cap.
        limit: u64,
    },
    /// An input is too large to be read whole within the memory budget.
    #[error("{}: reading its {} needs more memory than the budget's {}: free memory, or raise the budget with --max-memory", path.display(), edtmap_core::memory::format_bytes(*bytes), edtmap_core::memory::format_bytes(*limit))]
    OverBudget {
        /// The file.
        path: PathBuf,
        /// Its length.
        bytes: u64,
        /// The memory budget.
        limit: u64,
    },
    /// An output path is refused: a symbolic link, not a regular file, or
    /// named twice.
    #[error("{}: {reason}", path.display())]
    Output {
        /// The path.
        path: PathBuf,
        /// Why, and what to do instead.
        reason: String,
    },
    /// The file could not be opened, read or written.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        error: std::io::Error,
    },
    /// A recording (dataset folder or file) is malformed.
    #[error("{}: {reason}", path.display())]
    Dataset {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The file is not a valid `.npy` file.
    #[error("{}: not an npy file ({reason})", path.display())]
    NotNpy {
        /// The file.
        path: PathBuf,
        /// What is wrong with the header.
        reason: String,
    },
    /// An `.npy` file's data breaks its header's promise: bytes after the
    /// data, or bool elements that are neither 0 nor 1.
    #[error("{}: bad npy data: {reason}", path.display())]
    NpyData {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the counts or the element and its value.
        reason: String,
    },
    /// The array's element type is not accepted.
    #[error("{}: unsupported dtype {dtype} (expected bool or an integer type)", path.display())]
    UnsupportedDtype {
        /// The file.
        path: PathBuf,
        /// The dtype as written in the header.
        dtype: String,
    },
    /// The array's shape is not accepted.
    #[error("{}: shape {shape:?} is not accepted: {reason}", path.display())]
    BadShape {
        /// The file.
        path: PathBuf,
        /// The shape as written in the header.
        shape: Vec<u64>,
        /// Why it is refused.
        reason: String,
    },
    /// The file holds less data than its header promises.
    #[error("{}: truncated data: the header promises {expected} bytes, the file has {actual}", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Bytes of data the header implies.
        expected: u64,
        /// Bytes of data present.
        actual: u64,
    },
    /// Data handed to a writer does not match the shape.
    #[error("{}: {reason}", path.display())]
    BadData {
        /// The file.
        path: PathBuf,
        /// What does not match.
        reason: String,
    },
    /// A PCD file's header is malformed or inconsistent (missing or
    /// repeated keywords, FIELDS/SIZE/TYPE/COUNT of different lengths, bad
    /// numbers, WIDTH × HEIGHT ≠ POINTS, ...).
    #[error("{}: bad PCD header: {reason}", path.display())]
    PcdHeader {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the keyword or field and the value.
        reason: String,
    },
    /// A PCD file lacks one of the coordinate fields x, y, z, or stores it
    /// in a way that is not supported (only `F` of size 4 or 8, count 1).
    #[error("{}: PCD field {field}: {reason}", path.display())]
    PcdField {
        /// The file.
        path: PathBuf,
        /// The field: `x`, `y` or `z`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The PCD file's DATA encoding is not supported.
    #[error("{}: PCD DATA {encoding} is not supported (only ascii and binary are)", path.display())]
    PcdUnsupportedData {
        /// The file.
        path: PathBuf,
        /// The encoding named by the DATA line.
        encoding: String,
    },
    /// The ascii data of a PCD file is malformed: a bad number, a line
    /// with the wrong number of values, or fewer points than POINTS.
    #[error("{}: line {line}: {reason}", path.display())]
    PcdAscii {
        /// The file.
        path: PathBuf,
        /// Line number in the file, 1-based, header lines included.
        line: usize,
        /// What is wrong, naming the field and the value.
        reason: String,
    },
    /// A `.edtmap` map file cannot be read (not a map file, a newer format
    /// version, truncated, corrupt, invalid parameters) or a map cannot be
    /// saved (its contents fail the same checks).
    #[error("{}: {error}", path.display())]
    MapFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        error: crate::mapfile::MapFileError,
    },
}

impl IoError {
    /// An operating-system error on `path`.
    pub fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        IoError::Io { path: path.to_path_buf(), error: source }
    }
}

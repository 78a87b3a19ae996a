use std::path::PathBuf;

use thiserror::Error;

/// Errors drawing or writing a picture or a chart. Each names the file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum VizError {
    /// A chart cannot be drawn: an axis range that is empty, not finite or
    /// not positive on a log axis, or a picture size out of bounds.
    #[error("{}: cannot draw the chart: {reason}", path.display())]
    BadChart {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the axis or the size.
        reason: String,
    },
    /// The values handed to a picture writer do not match its size.
    #[error("{}: {reason}", path.display())]
    BadData {
        /// The file.
        path: PathBuf,
        /// What does not match.
        reason: String,
    },
    /// PNG encoding failed.
    #[error("{}: PNG encoding failed: {error}", path.display())]
    Png {
        /// The file.
        path: PathBuf,
        /// The encoder's message.
        error: png::EncodingError,
    },
    /// The file could not be written (refused output path, operating-system
    /// error), as `edtmap-io`'s atomic writer reports it.
    #[error(transparent)]
    Io(#[from] edtmap_io::IoError),
}

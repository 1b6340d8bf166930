//! Errors of the XML scene importer: every error names the file, the line and column, and the
//! element it is about, e.g. `scene.xml:12:5: <bsdf type="foo">: unknown plugin "foo"`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where an element starts: file, 1-based line and column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The XML file.
    pub file: Arc<Path>,
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub column: u32,
}

impl std::fmt::Display for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.column)
    }
}

/// A scene file could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file (or an included file) could not be read.
    // The cause is part of the message, not a `source` (`{:#}` chains would repeat it).
    #[error("{}: {error}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The file is not well-formed XML.
    #[error("{location}: malformed XML: {message}")]
    Syntax {
        /// Where the parser stopped.
        location: Location,
        /// The parser's message.
        message: String,
    },
    /// The XML is well-formed but an element is wrong: unknown plugin or parameter, bad value,
    /// missing file, dangling reference…
    #[error("{location}: {element}: {message}")]
    Element {
        /// Where the element starts.
        location: Location,
        /// The element as written, e.g. `<bsdf type="foo">`.
        element: String,
        /// What is wrong.
        message: String,
    },
}

impl SceneError {
    /// The location the error points at, if it has one (I/O errors on the top file do not).
    pub fn location(&self) -> Option<&Location> {
        match self {
            SceneError::Io { .. } => None,
            SceneError::Syntax { location, .. } | SceneError::Element { location, .. } => {
                Some(location)
            }
        }
    }
}

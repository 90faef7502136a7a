//! Typed errors and warnings of the library.
//!
//! Every input error carries a [`Location`] (`file:line[:column]`) so that the program can
//! point the user at the offending line, the way pbrt-v4 does. The library never prints and
//! never exits: it returns [`Error`] and collects [`Warning`]s in the values it builds.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file something was found.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Location {
    /// The file, as given by the user (or a built-in scene's name).
    pub file: PathBuf,
    /// 1-based line number, where the format has lines.
    pub line: Option<usize>,
    /// 1-based column, where known.
    pub column: Option<usize>,
}

impl Location {
    /// A location naming a whole file.
    pub fn file(file: impl Into<PathBuf>) -> Self {
        Location { file: file.into(), line: None, column: None }
    }
    /// A location naming a line of a file.
    pub fn line(file: impl Into<PathBuf>, line: usize) -> Self {
        Location { file: file.into(), line: Some(line), column: None }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        Ok(())
    }
}

/// The library's error type.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// Malformed or non-physical input, with the place it was found.
    #[error("{loc}: {msg}")]
    Input {
        /// File and line.
        loc: Location,
        /// What is wrong, in words.
        msg: String,
    },
    /// A request that cannot be honoured (bad option value, empty scene, ...).
    #[error("{0}")]
    Invalid(String),
    /// A computation would need more memory than allowed.
    #[error("{what} would need {} of memory (limit {}); {hint}", fmt_bytes(*needed), fmt_bytes(*limit))]
    TooLarge {
        /// What would be allocated.
        what: String,
        /// Bytes it would need.
        needed: u64,
        /// The configured limit in bytes.
        limit: u64,
        /// What to do instead.
        hint: String,
    },
    /// The user interrupted the work before any usable result existed.
    #[error("interrupted")]
    Cancelled,
    /// A solve that diverged or met a non-finite value: the cause and the worst elements
    /// (`places`: where their polygons were defined, filled in by the pipeline).
    #[error("{why}{}", if places.is_empty() { String::new() } else { format!("; worst polygons: {}", places.join(", ")) })]
    Diverged {
        /// What happened, in words.
        why: String,
        /// The elements with the largest values, worst first.
        elements: Vec<usize>,
        /// Their source polygons (`file:line`), when known.
        places: Vec<String>,
    },
}

impl Error {
    /// An input error at `loc`.
    pub fn input(loc: Location, msg: impl Into<String>) -> Self {
        Error::Input { loc, msg: msg.into() }
    }
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io { path: path.as_ref().to_path_buf(), source }
    }
}

/// Formats a byte count for people (`1.5 GiB`).
pub fn fmt_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// Convenience alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Something suspicious in the input that was handled (usually by skipping it).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Warning {
    /// Where, if known.
    pub loc: Option<Location>,
    /// What happened.
    pub msg: String,
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.loc {
            Some(l) => write!(f, "{l}: {}", self.msg),
            None => write!(f, "{}", self.msg),
        }
    }
}

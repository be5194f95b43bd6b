//! Errors of the world crate. Every error names where it happened: the file, the house index and,
//! for invalid houses, the offending field.

use std::path::PathBuf;

/// Where a house came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HouseLocation {
    /// The file it was read from (or `<generated>`).
    pub file: PathBuf,
    /// Its 0-based index (line) in that file.
    pub index: usize,
}

impl std::fmt::Display for HouseLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}, house {}", self.file.display(), self.index)
    }
}

/// Everything that can go wrong reading, checking or mapping a house.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// A file could not be opened, read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A house is not valid JSON or does not fit the schema.
    #[error("{at}: malformed JSON: {message}")]
    Malformed {
        /// Which house.
        at: HouseLocation,
        /// What the JSON parser said.
        message: String,
    },
    /// A house parsed but one of its fields is unusable.
    #[error("{at}: {field}: {message}")]
    Invalid {
        /// Which house.
        at: HouseLocation,
        /// The field path, e.g. `doors[2].wall0` or `rooms[1].floorPolygon`.
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// An asset database could not be read.
    #[error("asset database {file}: {message}")]
    AssetDatabase {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A house index range is empty or outside the file.
    #[error("{file}: {message}")]
    Range {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A file holds no house at all (it is empty or has blank lines only).
    #[error("{}: the file holds no houses (it is empty or has blank lines only)", file.display())]
    NoHouses {
        /// The file.
        file: PathBuf,
    },
    /// A house exceeds one of the input limits that keep memory bounded (line length,
    /// containers per house).
    #[error("{at}: {message}")]
    Limit {
        /// Which house.
        at: HouseLocation,
        /// What exceeds which limit.
        message: String,
    },
    /// Containers with no path to them from the start.
    #[error("{house}: {} unreachable container(s): {}", names.len(), names.join(", "))]
    Unreachable {
        /// The house label.
        house: String,
        /// Human names of the unreachable containers.
        names: Vec<String>,
    },
    /// A ROS map (YAML + image) cannot be used.
    #[error("{}: {}{message}", file.display(), field_prefix(field))]
    Map {
        /// The YAML or image file.
        file: PathBuf,
        /// The field, e.g. `resolution` or `image`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A scene file is malformed or inconsistent.
    #[error("{}: {}{message}", file.display(), field_prefix(field))]
    Scene {
        /// The scene file.
        file: PathBuf,
        /// The field path, e.g. `containers[3].room`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The occupancy grid cannot be built (e.g. the start is not on any floor).
    #[error("{house}: {message}")]
    Grid {
        /// The house label.
        house: String,
        /// What is wrong.
        message: String,
    },
}

/// `field: `, or nothing for an error about the whole file.
fn field_prefix(field: &str) -> String {
    if field.is_empty() {
        String::new()
    } else {
        format!("{field}: ")
    }
}

/// Result alias for this crate.
pub type Result<T, E = WorldError> = std::result::Result<T, E>;

/// An error and its causes as one line, `message: cause: cause…`, skipping a cause already
/// spelled out in the text before it (many errors embed their source, e.g. `file: No such file
/// or directory`, and some only say "error sending request" while the cause says why).
pub fn error_chain(e: &dyn std::error::Error) -> String {
    let mut msg = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        let c = cause.to_string();
        if !msg.contains(&c) {
            msg.push_str(": ");
            msg.push_str(&c);
        }
        source = cause.source();
    }
    msg
}

#[cfg(test)]
mod chain_tests {
    use super::error_chain;

    #[derive(Debug)]
    struct E(&'static str, Option<Box<E>>);
    impl std::fmt::Display for E {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str(self.0)
        }
    }
    impl std::error::Error for E {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            self.1.as_deref().map(|e| e as _)
        }
    }

    #[test]
    fn causes_are_joined_and_those_already_said_are_skipped() {
        let e = E(
            "error sending request",
            Some(Box::new(E(
                "connect: refused",
                Some(Box::new(E("refused", None))),
            ))),
        );
        assert_eq!(error_chain(&e), "error sending request: connect: refused");
        assert_eq!(error_chain(&E("alone", None)), "alone");
    }
}

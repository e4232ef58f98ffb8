//! The one error type of the cooker. Every message is a single line that starts with the file it
//! is about, so a CLI can print it as-is and a test can match on it.

/// Why a cook (or reading a cooked pack back) failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CookError {
    #[error("{file}: no such file")]
    NotFound { file: String },
    #[error("{file}: not a glTF 2.0 file: {reason}")]
    NotGltf { file: String, reason: String },
    /// The file is glTF but its content is broken; `problem` names the object (mesh, accessor,
    /// image...) and what is wrong with it.
    #[error("{file}: {problem}")]
    Invalid { file: String, problem: String },
    /// Reading or writing failed for a reason outside the content (permissions, missing directory).
    #[error("{file}: {problem}")]
    Io { file: String, problem: String },
    #[error("{file}: {reason}")]
    BadPack { file: String, reason: String },
}

impl CookError {
    pub(crate) fn invalid(file: &str, problem: impl Into<String>) -> Self {
        CookError::Invalid { file: file.into(), problem: one_line(&problem.into()) }
    }
    pub(crate) fn io(file: &str, problem: impl Into<String>) -> Self {
        CookError::Io { file: file.into(), problem: one_line(&problem.into()) }
    }
}

/// Messages from libraries (JSON parser, image decoders) may span lines; ours must not.
pub(crate) fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

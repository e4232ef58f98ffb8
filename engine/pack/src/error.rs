/// Why a pack could not be read. Each kind of damage has its own variant so that tools and tests
/// can tell them apart; the messages are written for the person who has to fix the file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PackError {
    #[error("not a pack file (it does not start with the pack magic \"GAMEPACK\")")]
    NotAPack,
    #[error("pack format version {found} is not supported (this build reads version {supported}); re-cook the content")]
    WrongVersion { found: u32, supported: u32 },
    #[error("truncated pack: the header says {expected} bytes but the file has {actual}")]
    Truncated { expected: u64, actual: u64 },
    #[error("corrupt pack: checksum mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    ChecksumMismatch { stored: u32, computed: u32 },
    #[error("corrupt pack: {0}")]
    Corrupt(String),
    #[error("malformed pack: {0}")]
    Malformed(String),
    #[error("{0}")]
    Io(String),
}

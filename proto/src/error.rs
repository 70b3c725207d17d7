//! The one error type of the codec and framing, with a coarse [`ErrorKind`]
//! that routers and agents use as a counter key.

/// Why bytes could not become a message, or a message could not become bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// Zero bytes where a message was expected.
    #[error("empty message")]
    Empty,
    /// More bytes than [`crate::MAX_MESSAGE_LEN`]; the input was not parsed.
    #[error("message of {len} bytes exceeds the {max}-byte limit")]
    Oversized { len: usize, max: usize },
    /// The sender speaks another protocol version.
    #[error("protocol version {found} is not supported (this build speaks version {supported})")]
    Version { found: u64, supported: u8 },
    /// The header names a message kind this build does not know.
    #[error("unknown message kind {0}")]
    UnknownKind(u64),
    /// Not a well-formed MECH message: truncated, wrong types or shape.
    #[error("malformed message: {0}")]
    Malformed(String),
    /// Well-formed, but a field is out of range (NaN speed, name too long...).
    #[error("invalid message: {0}")]
    Invalid(String),
    /// A serial frame whose CRC-32 does not match its contents.
    #[error("frame checksum mismatch: frame says {expected:#010x}, contents give {computed:#010x}")]
    Checksum { expected: u32, computed: u32 },
    /// A serial or stream frame that cannot be undone (bad COBS, short frame).
    #[error("bad frame: {0}")]
    Framing(&'static str),
    /// A message could not be encoded (only for invalid values).
    #[error("cannot encode message: {0}")]
    Encode(String),
}

crate::named_enum! {
    /// Coarse classes of [`Error`], for counters ("dropped: 3 malformed, 1 version").
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
    pub enum ErrorKind: "error kind" {
        Empty => "empty",
        Oversized => "oversized",
        Version => "version",
        UnknownKind => "unknown-kind",
        Malformed => "malformed",
        Invalid => "invalid",
        Checksum => "checksum",
        Framing => "framing",
        Encode => "encode",
    }
}

impl Error {
    /// The class of this error.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Empty => ErrorKind::Empty,
            Error::Oversized { .. } => ErrorKind::Oversized,
            Error::Version { .. } => ErrorKind::Version,
            Error::UnknownKind(_) => ErrorKind::UnknownKind,
            Error::Malformed(_) => ErrorKind::Malformed,
            Error::Invalid(_) => ErrorKind::Invalid,
            Error::Checksum { .. } => ErrorKind::Checksum,
            Error::Framing(_) => ErrorKind::Framing,
            Error::Encode(_) => ErrorKind::Encode,
        }
    }

    pub(crate) fn invalid(text: impl Into<String>) -> Error {
        Error::Invalid(text.into())
    }
}

//! The rule every name in a message follows (robots, platforms, channels,
//! clusters): bounded length, no whitespace or control characters.

use crate::MAX_NAME_LEN;
use crate::error::Error;

/// Checks a name that may be empty (an unset destination, say).
pub(crate) fn name(v: &str, what: &str) -> Result<(), Error> {
    if v.len() > MAX_NAME_LEN {
        return Err(Error::invalid(format!(
            "{what} is {} bytes long, at most {MAX_NAME_LEN} allowed",
            v.len()
        )));
    }
    if v.chars().any(|c| c.is_control() || c.is_whitespace()) {
        return Err(Error::invalid(format!(
            "{what} {v:?} contains whitespace or control characters"
        )));
    }
    Ok(())
}

/// Checks a name that must be given.
pub(crate) fn nonempty_name(v: &str, what: &str) -> Result<(), Error> {
    if v.is_empty() {
        return Err(Error::invalid(format!("{what} is empty")));
    }
    name(v, what)
}

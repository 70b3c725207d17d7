//! Operators' names: what a name in channel names and logs may be, and the
//! name a process attaches under when it is given none (its user's login).

/// An operator's name as the station uses it in channel names
/// (`joy/NAME/0`) and logs: 1 to 32 letters, digits, `_`, `-` or `.`.
pub fn check_operator(name: &str) -> Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= 32
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "operator name {name:?} must be 1 to 32 letters, digits, '_', '-' or '.'"
        ))
    }
}

/// The login name of the user running this process (the default operator
/// name), or `operator`.
pub fn login_name() -> String {
    let uid = nix::unistd::getuid();
    nix::unistd::User::from_uid(uid)
        .ok()
        .flatten()
        .map(|u| u.name)
        .filter(|n| check_operator(n).is_ok())
        .unwrap_or_else(|| "operator".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn operator_names_are_channel_safe() {
        for good in ["ana", "b.o_b-2", "x"] {
            assert!(check_operator(good).is_ok(), "{good}");
        }
        for bad in ["", "a b", "a/b", "ana#", &"x".repeat(33), "é"] {
            assert!(check_operator(bad).is_err(), "{bad}");
        }
    }
}

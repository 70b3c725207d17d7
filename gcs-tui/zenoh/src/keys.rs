//! The key space on Zenoh (`docs/zenoh.md`): every key starts `mech/`,
//! then the station's name, then the robot's, then what it carries.
//!
//! ```text
//! mech/<station>                          liveliness: the station's bridge is up
//! mech/<station>/<robot>                  liveliness: the robot is connected to it
//! mech/<station>/<robot>/info             registration (platform, capabilities, limits)
//! mech/<station>/<robot>/telemetry        every telemetry the station receives
//! mech/<station>/<robot>/link             connected | stale | lost, on change
//! mech/<station>/<robot>/route            the robot's route, on change
//! mech/<station>/<robot>/cmd/<channel>    commands into the station (channel may hold `/`)
//! mech/<station>/<robot>/route/request    route requests (a query, answered)
//! ```
//!
//! A station, robot or channel name goes into a key only if every chunk of
//! it is a plain Zenoh key chunk: not empty, and free of `/` (within a
//! name), the wildcards `*` and `$`, `?` and `#` (which end a key), `@`
//! (a verbatim chunk, and the `robot@station` separator here), whitespace
//! and control characters.

/// The first chunk of every key.
pub const ROOT: &str = "mech";

/// Characters a name may not hold in a key chunk.
const FORBIDDEN: &[char] = &['/', '*', '$', '?', '#', '@'];

/// A name that cannot be (part of) a key, or a key that is not one of ours.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    #[error("{what} name is empty: it cannot be a Zenoh key chunk")]
    Empty { what: &'static str },
    #[error(
        "{what} name {name:?} cannot be a Zenoh key chunk: it contains {found:?} \
         (names on Zenoh may not hold / * $ ? # @, whitespace or control characters)"
    )]
    Forbidden {
        what: &'static str,
        name: String,
        found: char,
    },
    #[error("key {0:?} is not in MECH's key space (mech/<station>/<robot>/...)")]
    Foreign(String),
}

/// Checks that `name` can be one key chunk.
pub fn check_name(what: &'static str, name: &str) -> Result<(), KeyError> {
    if name.is_empty() {
        return Err(KeyError::Empty { what });
    }
    let bad = name
        .chars()
        .find(|c| FORBIDDEN.contains(c) || c.is_whitespace() || c.is_control());
    match bad {
        Some(found) => Err(KeyError::Forbidden {
            what,
            name: name.to_string(),
            found,
        }),
        None => Ok(()),
    }
}

/// Checks that `channel` can end a key: each of its `/`-separated chunks
/// is a plain key chunk (so `ext/matlab` is two chunks, `ext//x` is not a
/// channel on Zenoh).
pub fn check_channel(channel: &str) -> Result<(), KeyError> {
    if channel.is_empty() {
        return Err(KeyError::Empty { what: "channel" });
    }
    for chunk in channel.split('/') {
        check_name("channel", chunk).map_err(|e| match e {
            KeyError::Empty { .. } => KeyError::Forbidden {
                what: "channel",
                name: channel.to_string(),
                found: '/',
            },
            KeyError::Forbidden { found, .. } => KeyError::Forbidden {
                what: "channel",
                name: channel.to_string(),
                found,
            },
            other => other,
        })?;
    }
    Ok(())
}

mech_proto::named_enum! {
    /// What a robot's state key carries.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum Topic: "topic" {
        Info => "info",
        Telemetry => "telemetry",
        Link => "link",
        Route => "route",
    }
}

/// `mech/<station>`: the station's liveliness token.
pub fn station_token(station: &str) -> String {
    format!("{ROOT}/{station}")
}

/// `mech/<station>/<robot>`: the robot's liveliness token.
pub fn robot_token(station: &str, robot: &str) -> String {
    format!("{ROOT}/{station}/{robot}")
}

/// `mech/<station>/<robot>/<topic>`.
pub fn state_key(station: &str, robot: &str, topic: Topic) -> String {
    format!("{ROOT}/{station}/{robot}/{}", topic.as_str())
}

/// `mech/<station>/<robot>/cmd/<channel>`.
pub fn command_key(station: &str, robot: &str, channel: &str) -> String {
    format!("{ROOT}/{station}/{robot}/cmd/{channel}")
}

/// `mech/<station>/<robot>/route/request`.
pub fn route_request_key(station: &str, robot: &str) -> String {
    format!("{ROOT}/{station}/{robot}/route/request")
}

/// A key of MECH's key space, split into its parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Key<'a> {
    Station {
        station: &'a str,
    },
    Robot {
        station: &'a str,
        robot: &'a str,
    },
    State {
        station: &'a str,
        robot: &'a str,
        topic: Topic,
    },
    Command {
        station: &'a str,
        robot: &'a str,
        channel: &'a str,
    },
    RouteRequest {
        station: &'a str,
        robot: &'a str,
    },
}

/// Splits a key heard on Zenoh; its station, robot and channel names are
/// checked as [`check_name`] and [`check_channel`] do.
pub fn parse(key: &str) -> Result<Key<'_>, KeyError> {
    let foreign = || KeyError::Foreign(key.to_string());
    let rest = key.strip_prefix(ROOT).ok_or_else(foreign)?;
    let rest = rest.strip_prefix('/').ok_or_else(foreign)?;
    let (station, rest) = rest.split_once('/').unwrap_or((rest, ""));
    check_name("station", station)?;
    if rest.is_empty() {
        return Ok(Key::Station { station });
    }
    let (robot, rest) = rest.split_once('/').unwrap_or((rest, ""));
    check_name("robot", robot)?;
    if rest.is_empty() {
        return Ok(Key::Robot { station, robot });
    }
    if let Some(channel) = rest.strip_prefix("cmd/") {
        check_channel(channel)?;
        return Ok(Key::Command {
            station,
            robot,
            channel,
        });
    }
    if rest == "route/request" {
        return Ok(Key::RouteRequest { station, robot });
    }
    let topic = Topic::parse(rest).ok_or_else(foreign)?;
    Ok(Key::State {
        station,
        robot,
        topic,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_with_key_syntax_are_refused_with_the_character() {
        for (name, found) in [
            ("a/b", '/'),
            ("r*", '*'),
            ("$x", '$'),
            ("what?", '?'),
            ("x#1", '#'),
            ("r@s", '@'),
            ("two words", ' '),
            ("tab\t", '\t'),
        ] {
            let e = check_name("robot", name).unwrap_err();
            assert_eq!(
                e,
                KeyError::Forbidden {
                    what: "robot",
                    name: name.into(),
                    found
                }
            );
            assert!(e.to_string().contains(&format!("{name:?}")), "{e}");
        }
        assert_eq!(
            check_name("station", ""),
            Err(KeyError::Empty { what: "station" })
        );
        check_name("robot", "robot_1.kiwi-2").unwrap();
    }

    #[test]
    fn channels_may_have_several_chunks_but_no_empty_one() {
        check_channel("ext/matlab").unwrap();
        check_channel("joy/0").unwrap();
        for bad in ["", "ext//x", "/x", "x/", "fleet/*", "a/**", "x?y"] {
            assert!(check_channel(bad).is_err(), "{bad:?}");
        }
        assert!(
            check_channel("ext//x")
                .unwrap_err()
                .to_string()
                .contains("\"ext//x\"")
        );
    }

    #[test]
    fn keys_are_built_and_split_the_same_way() {
        assert_eq!(station_token("site-a"), "mech/site-a");
        assert_eq!(
            parse(&robot_token("site-a", "r1")).unwrap(),
            Key::Robot {
                station: "site-a",
                robot: "r1"
            }
        );
        for topic in Topic::ALL {
            let key = state_key("site-a", "r1", topic);
            assert_eq!(
                parse(&key).unwrap(),
                Key::State {
                    station: "site-a",
                    robot: "r1",
                    topic
                }
            );
        }
        assert_eq!(
            parse(&command_key("site-a", "r1", "ext/matlab")).unwrap(),
            Key::Command {
                station: "site-a",
                robot: "r1",
                channel: "ext/matlab"
            }
        );
        assert_eq!(
            parse(&route_request_key("s", "r")).unwrap(),
            Key::RouteRequest {
                station: "s",
                robot: "r"
            }
        );
        assert_eq!(parse("mech/s").unwrap(), Key::Station { station: "s" });
    }

    #[test]
    fn foreign_keys_and_bad_parts_are_errors() {
        for key in [
            "mech",
            "other/s/r/telemetry",
            "mechx/s",
            "mech/s/r/pose",
            "mech/s/r/route/other",
            "mech/s/r/cmd/",
        ] {
            assert!(parse(key).is_err(), "{key}");
        }
        assert!(matches!(
            parse("mech/s/r@x/telemetry"),
            Err(KeyError::Forbidden { found: '@', .. })
        ));
        assert!(matches!(
            parse("mech/s/r/cmd/a//b"),
            Err(KeyError::Forbidden { .. })
        ));
    }
}

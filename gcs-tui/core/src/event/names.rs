//! The names events are tagged with, read from the type: serde's derive
//! keeps the list of an enum's variant names (its renames applied), and
//! hands it to the error of a tag it does not know. Reading an event
//! whose tag is no name at all, through a deserializer whose error keeps
//! that list, gives the list itself: the one the recorder and the script
//! output tag events with, so nothing else has to repeat it.

use serde::Deserialize;
use serde::de::value::MapDeserializer;

use super::Event;

/// The event tag serde writes ([`Event`]'s `#[serde(tag)]`).
const TAG: &str = "event";

/// What reading the nameless event ended with.
#[derive(Debug)]
enum Found {
    /// The tag was refused as an unknown variant: the variants it may be.
    Names(&'static [&'static str]),
    /// Anything else (which a change in serde's derive could bring).
    Other(String),
}

impl std::fmt::Display for Found {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Found::Names(names) => write!(f, "event names {names:?}"),
            Found::Other(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for Found {}

impl serde::de::Error for Found {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        Found::Other(msg.to_string())
    }

    fn unknown_variant(_variant: &str, expected: &'static [&'static str]) -> Self {
        Found::Names(expected)
    }
}

/// Every event's name, in the order the variants are declared.
pub(super) fn all() -> &'static [&'static str] {
    // No name is empty: serde refuses the tag and says which it knows.
    let nameless = MapDeserializer::<_, Found>::new(std::iter::once((TAG, "")));
    match Event::deserialize(nameless) {
        Err(Found::Names(names)) => names,
        // The tests read every name; a serde that stopped saying them
        // fails there, not in a recording.
        Err(Found::Other(_)) | Ok(_) => &[],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_names_are_the_tags_serde_writes_renames_and_all() {
        let names = all();
        assert_eq!(names.first(), Some(&"listening"));
        let estop = Event::EStop {
            engage: true,
            id: 1,
        };
        let tag = serde_json::to_value(&estop).unwrap()[TAG].clone();
        assert_eq!(tag, "estop");
        assert!(names.contains(&"estop") && !names.contains(&"e_stop"));
        let mut unique = names.to_vec();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len());
    }
}

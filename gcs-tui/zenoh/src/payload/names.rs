//! How a few fields are written on Zenoh where the protocol's own form is
//! not what a reader of JSON expects: a channel of none is `null` (the wire
//! has it empty), capabilities are names (the wire has numbers). The
//! protocol's small enums are written by the names they are declared with
//! (`mech_proto::named::by_name`).

/// A channel name, `null` for none (the protocol writes none as empty).
pub mod channel {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(c: &str, s: S) -> Result<S::Ok, S::Error> {
        match c {
            "" => s.serialize_none(),
            c => s.serialize_some(c),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<String, D::Error> {
        Ok(Option::<String>::deserialize(d)?.unwrap_or_default())
    }
}

/// Command kinds a robot obeys, by name; a name this version does not
/// know is left out (a later version may add kinds).
pub mod capabilities {
    use mech_proto::CommandKind;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(kinds: &[CommandKind], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(kinds.iter().map(|k| k.as_str()))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<CommandKind>, D::Error> {
        let names = Vec::<String>::deserialize(d)?;
        Ok(names.iter().filter_map(|n| CommandKind::parse(n)).collect())
    }
}

#[cfg(test)]
mod tests {
    use mech_core::LinkState;
    use mech_proto::{
        CommandKind, Computation, ControlMode, FailsafeState, Health, VelocitySource,
    };

    /// The names `docs/zenoh.md` lists, in its order.
    #[test]
    fn every_name_reads_back() {
        fn names<T: mech_proto::Named>() -> Vec<&'static str> {
            let all: Vec<&str> = T::VARIANTS.iter().map(|v| v.name()).collect();
            for (v, n) in T::VARIANTS.iter().zip(&all) {
                assert_eq!(T::from_name(n).map(|b| b.name()), Some(v.name()));
            }
            all
        }
        assert_eq!(
            names::<ControlMode>(),
            [
                "idle",
                "actuators",
                "steering-throttle",
                "velocity-heading",
                "twist",
                "waypoints",
                "stopped"
            ]
        );
        assert_eq!(names::<Computation>(), ["onboard", "offboard"]);
        assert_eq!(
            names::<FailsafeState>(),
            ["ok", "channel-silent", "router-lost", "estopped", "fault"]
        );
        assert_eq!(names::<Health>(), ["ok", "degraded", "fault"]);
        assert_eq!(names::<VelocitySource>(), ["commanded", "measured"]);
        assert_eq!(names::<LinkState>(), ["connected", "stale", "lost"]);
        assert_eq!(
            names::<CommandKind>(),
            [
                "actuators",
                "steering-throttle",
                "velocity-heading",
                "twist",
                "waypoints",
                "stop"
            ]
        );
        assert_eq!(LinkState::parse("lost"), Some(LinkState::Lost));
        assert_eq!(ControlMode::parse("Twist"), None);
    }
}

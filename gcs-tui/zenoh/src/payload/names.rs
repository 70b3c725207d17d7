//! The protocol's small enums as JSON strings (the wire has them as
//! numbers; a reader of JSON should not need a table), each a serde `with`
//! module: `#[serde(with = "names::mode")]`.

macro_rules! names {
    ($(#[$doc:meta])* $module:ident: $ty:ty { $($variant:expr => $name:literal),+ $(,)? }) => {
        $(#[$doc])*
        pub mod $module {
            use serde::{Deserialize, Deserializer, Serializer};

            pub fn name(v: $ty) -> &'static str {
                $(if v == $variant { return $name; })+
                unreachable!("every variant is listed")
            }

            pub fn parse(s: &str) -> Option<$ty> {
                match s {
                    $($name => Some($variant),)+
                    _ => None,
                }
            }

            pub fn serialize<S: Serializer>(v: &$ty, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_str(name(*v))
            }

            pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<$ty, D::Error> {
                let s = String::deserialize(d)?;
                parse(&s).ok_or_else(|| {
                    let known = [$($name),+].join(", ");
                    serde::de::Error::custom(format!(
                        "unknown {} {s:?} (one of {known})",
                        stringify!($module)
                    ))
                })
            }
        }
    };
}

names! {
    /// What the robot does with its actuators.
    mode: mech_proto::ControlMode {
        mech_proto::ControlMode::Idle => "idle",
        mech_proto::ControlMode::Actuators => "actuators",
        mech_proto::ControlMode::SteeringThrottle => "steering-throttle",
        mech_proto::ControlMode::VelocityHeading => "velocity-heading",
        mech_proto::ControlMode::Twist => "twist",
        mech_proto::ControlMode::Waypoints => "waypoints",
        mech_proto::ControlMode::Stopped => "stopped",
    }
}

names! {
    /// Where the closed loop runs.
    computation: mech_proto::Computation {
        mech_proto::Computation::Onboard => "onboard",
        mech_proto::Computation::Offboard => "offboard",
    }
}

names! {
    /// Why the actuators are held at zero, as the command language writes it.
    failsafe: mech_proto::FailsafeState {
        mech_proto::FailsafeState::Ok => "ok",
        mech_proto::FailsafeState::ChannelSilent => "channel-silent",
        mech_proto::FailsafeState::RouterLost => "router-lost",
        mech_proto::FailsafeState::EStopped => "estopped",
        mech_proto::FailsafeState::Fault => "fault",
    }
}

names! {
    /// The agent's own judgement of its health.
    health: mech_proto::Health {
        mech_proto::Health::Ok => "ok",
        mech_proto::Health::Degraded => "degraded",
        mech_proto::Health::Fault => "fault",
    }
}

names! {
    /// Whether the velocity was measured or follows from the commands.
    velocity_source: mech_proto::VelocitySource {
        mech_proto::VelocitySource::Commanded => "commanded",
        mech_proto::VelocitySource::Measured => "measured",
    }
}

names! {
    /// How recently the station heard from the robot.
    link: mech_core::LinkState {
        mech_core::LinkState::Connected => "connected",
        mech_core::LinkState::Stale => "stale",
        mech_core::LinkState::Lost => "lost",
    }
}

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
    use mech_proto::{Computation, ControlMode, FailsafeState, Health, VelocitySource};

    #[test]
    fn every_name_reads_back() {
        for m in [
            ControlMode::Idle,
            ControlMode::Actuators,
            ControlMode::SteeringThrottle,
            ControlMode::VelocityHeading,
            ControlMode::Twist,
            ControlMode::Waypoints,
            ControlMode::Stopped,
        ] {
            assert_eq!(super::mode::parse(super::mode::name(m)), Some(m));
        }
        for c in [Computation::Onboard, Computation::Offboard] {
            assert_eq!(
                super::computation::parse(super::computation::name(c)),
                Some(c)
            );
        }
        for f in [
            FailsafeState::Ok,
            FailsafeState::ChannelSilent,
            FailsafeState::RouterLost,
            FailsafeState::EStopped,
            FailsafeState::Fault,
        ] {
            assert_eq!(super::failsafe::parse(super::failsafe::name(f)), Some(f));
        }
        for h in [Health::Ok, Health::Degraded, Health::Fault] {
            assert_eq!(super::health::parse(super::health::name(h)), Some(h));
        }
        for v in [VelocitySource::Commanded, VelocitySource::Measured] {
            let name = super::velocity_source::name(v);
            assert_eq!(super::velocity_source::parse(name), Some(v));
        }
        assert_eq!(super::link::parse("lost"), Some(mech_core::LinkState::Lost));
        assert_eq!(super::mode::parse("Twist"), None);
    }
}

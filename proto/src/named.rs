//! Names of small enums: the one place a variant's written name (in a
//! config file, the command language, JSON, a log line) is declared. The
//! `named_enum!` macro writes the enum and, from the same list, its
//! `ALL`, `as_str`, `parse`, `Display` and [`Named`], so a name is never
//! spelt in a second table that could drift from the first; [`by_name`]
//! and `serde_by_name!` write and read such an enum by its names in serde
//! formats (JSON, TOML).

/// An enum whose every variant has a written name (made by
/// [`named_enum!`](crate::named_enum)), for code that reads or writes any
/// of them: a serde field by name, an error listing the names.
pub trait Named: Copy + Sized + 'static {
    /// What a value is, for messages: `"control mode"`.
    const WHAT: &'static str;
    /// Every variant, in declaration order.
    const VARIANTS: &'static [Self];

    /// The variant's written name.
    fn name(self) -> &'static str;

    /// The variant written `name` (exactly: names are case-sensitive).
    fn from_name(name: &str) -> Option<Self> {
        Self::VARIANTS.iter().copied().find(|v| v.name() == name)
    }

    /// Every name, comma-separated, for an error that lists them.
    fn names() -> String {
        let names: Vec<&str> = Self::VARIANTS.iter().map(|v| v.name()).collect();
        names.join(", ")
    }
}

/// Declares a field-less enum with the name each variant is written as:
///
/// ```
/// mech_proto::named_enum! {
///     /// How recently a robot was heard.
///     #[derive(Debug, Clone, Copy, PartialEq, Eq)]
///     pub enum Freshness: "freshness" {
///         /// Heard within the timeout.
///         Fresh => "fresh",
///         Stale => "stale",
///     }
/// }
/// assert_eq!(Freshness::ALL, [Freshness::Fresh, Freshness::Stale]);
/// assert_eq!(Freshness::Stale.as_str(), "stale");
/// assert_eq!(Freshness::parse("fresh"), Some(Freshness::Fresh));
/// assert_eq!(Freshness::parse("Fresh"), None);
/// assert_eq!(Freshness::Stale.to_string(), "stale");
/// ```
///
/// A variant may carry a discriminant before its name (`Twist = 4 =>
/// "twist"`), for enums that travel as numbers. The string after the enum's
/// name says what a value is ([`Named::WHAT`]). The enum must derive `Clone`
/// and `Copy`.
#[macro_export]
macro_rules! named_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident: $what:literal {
            $( $(#[$vmeta:meta])* $variant:ident $(= $value:literal)? => $text:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis enum $name {
            $( $(#[$vmeta])* $variant $(= $value)?, )+
        }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: [$name; [$($text),+].len()] = [$($name::$variant),+];

            /// The written name (config, command language, JSON, logs).
            pub const fn as_str(self) -> &'static str {
                match self {
                    $( $name::$variant => $text, )+
                }
            }

            /// The variant written `name` ([`Self::as_str`]), exactly.
            pub fn parse(name: &str) -> Option<$name> {
                match name {
                    $( $text => Some($name::$variant), )+
                    _ => None,
                }
            }
        }

        impl ::core::fmt::Display for $name {
            fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl $crate::Named for $name {
            const WHAT: &'static str = $what;
            const VARIANTS: &'static [$name] = &$name::ALL;

            fn name(self) -> &'static str {
                self.as_str()
            }

            fn from_name(name: &str) -> Option<$name> {
                $name::parse(name)
            }
        }
    };
}

/// serde by name, for a field: `#[serde(with = "mech_proto::named::by_name")]`
/// on a field of any [`Named`] type. A name that is not one of the type's
/// is an error that lists them.
pub mod by_name {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    use super::Named;

    pub fn serialize<T: Named, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(v.name())
    }

    pub fn deserialize<'de, T: Named, D: Deserializer<'de>>(d: D) -> Result<T, D::Error> {
        let name = String::deserialize(d)?;
        T::from_name(&name).ok_or_else(|| {
            D::Error::custom(format_args!(
                "unknown {} {name:?} (one of {})",
                T::WHAT,
                T::names()
            ))
        })
    }
}

/// serde by name for a whole [`Named`] type (`mech_proto::serde_by_name!(LinkState);`):
/// its `Serialize` and `Deserialize` write and read the names
/// `named_enum!` gave it, so serde never keeps a second spelling.
#[macro_export]
macro_rules! serde_by_name {
    ($name:ty) => {
        impl $crate::named::__serde::Serialize for $name {
            fn serialize<S: $crate::named::__serde::Serializer>(
                &self,
                s: S,
            ) -> ::core::result::Result<S::Ok, S::Error> {
                $crate::named::by_name::serialize(self, s)
            }
        }

        impl<'de> $crate::named::__serde::Deserialize<'de> for $name {
            fn deserialize<D: $crate::named::__serde::Deserializer<'de>>(
                d: D,
            ) -> ::core::result::Result<$name, D::Error> {
                $crate::named::by_name::deserialize(d)
            }
        }
    };
}

#[doc(hidden)]
pub use serde as __serde;

#[cfg(test)]
mod tests {
    use super::Named;

    crate::named_enum! {
        /// A test enum with wire numbers.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(u8)]
        enum Numbered: "numbered thing" {
            /// The first.
            One = 1 => "one",
            Three = 3 => "three",
        }
    }

    #[test]
    fn names_numbers_and_the_trait_agree() {
        assert_eq!(Numbered::ALL, [Numbered::One, Numbered::Three]);
        assert_eq!(Numbered::Three as u8, 3);
        for v in Numbered::ALL {
            assert_eq!(Numbered::parse(v.as_str()), Some(v));
            assert_eq!(<Numbered as Named>::from_name(v.name()), Some(v));
            assert_eq!(v.to_string(), v.as_str());
        }
        assert_eq!(Numbered::parse("two"), None);
        assert_eq!(Numbered::names(), "one, three");
        assert_eq!(Numbered::WHAT, "numbered thing");
    }

    crate::serde_by_name!(Numbered);

    #[test]
    fn serde_by_name_writes_and_reads_the_names() {
        assert_eq!(
            serde_json::to_string(&Numbered::Three).unwrap(),
            r#""three""#
        );
        let back: Numbered = serde_json::from_str(r#""one""#).unwrap();
        assert_eq!(back, Numbered::One);
        let e = serde_json::from_str::<Numbered>(r#""two""#).unwrap_err();
        assert_eq!(
            e.to_string(),
            r#"unknown numbered thing "two" (one of one, three)"#
        );
    }
}

//! The `tagged_enum!` macro: enums whose variants each carry one payload and
//! travel as a small integer kind followed by that payload.
//!
//! serde's default enum encoding spells variant names out; MECH sends an
//! integer kind instead so the wire stays compact and clients in other
//! languages only need a table of numbers (see `docs/protocol.md`).

/// Declares an enum of newtype variants, each with a fixed wire kind, and
/// generates `kind()`, `name()`, `is_known()`, `write_payload()`,
/// `read_payload()`, and serde impls that encode it as `[kind, payload]`.
macro_rules! tagged_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $( $(#[$vmeta:meta])* $variant:ident($payload:ty) = $kind:literal, )*
        }
    ) => {
        $(#[$meta])*
        pub enum $name {
            $( $(#[$vmeta])* $variant($payload), )*
        }

        impl $name {
            /// The wire kind of this variant.
            pub fn kind(&self) -> u8 {
                match self { $( $name::$variant(_) => $kind, )* }
            }

            /// The variant's name, for logs and error messages.
            pub fn name(&self) -> &'static str {
                match self { $( $name::$variant(_) => stringify!($variant), )* }
            }

            /// Whether `kind` names a variant this build knows.
            pub fn is_known(kind: u64) -> bool {
                #[allow(clippy::manual_range_patterns)]
                let known = matches!(kind, $( $kind )|*);
                known
            }

            /// Writes the payload (without the kind) as the next tuple element.
            pub(crate) fn write_payload<T: serde::ser::SerializeTuple>(
                &self,
                tuple: &mut T,
            ) -> Result<(), T::Error> {
                match self { $( $name::$variant(p) => tuple.serialize_element(p), )* }
            }

            /// Reads the payload for `kind` as the next sequence element.
            pub(crate) fn read_payload<'de, A: serde::de::SeqAccess<'de>>(
                kind: u8,
                seq: &mut A,
            ) -> Result<Self, A::Error> {
                use serde::de::Error as _;
                match kind {
                    $( $kind => seq
                        .next_element::<$payload>()?
                        .map($name::$variant)
                        .ok_or_else(|| A::Error::custom(concat!("missing payload of ", stringify!($variant)))), )*
                    other => Err(A::Error::custom(format_args!(
                        "unknown {} kind {}", stringify!($name), other
                    ))),
                }
            }
        }

        impl serde::Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                use serde::ser::SerializeTuple;
                let mut t = s.serialize_tuple(2)?;
                t.serialize_element(&self.kind())?;
                self.write_payload(&mut t)?;
                t.end()
            }
        }

        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                struct KindVisitor;
                impl<'de> serde::de::Visitor<'de> for KindVisitor {
                    type Value = $name;
                    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                        f.write_str(concat!("a [kind, payload] array for ", stringify!($name)))
                    }
                    fn visit_seq<A: serde::de::SeqAccess<'de>>(
                        self,
                        mut seq: A,
                    ) -> Result<$name, A::Error> {
                        let kind: u8 = seq
                            .next_element()?
                            .ok_or_else(|| serde::de::Error::invalid_length(0, &self))?;
                        let value = $name::read_payload(kind, &mut seq)?;
                        $crate::tagged::expect_end(&mut seq, stringify!($name))?;
                        Ok(value)
                    }
                }
                d.deserialize_tuple(2, KindVisitor)
            }
        }
    };
}

pub(crate) use tagged_enum;

/// Rejects trailing elements of a sequence that should be complete.
pub(crate) fn expect_end<'de, A: serde::de::SeqAccess<'de>>(
    seq: &mut A,
    what: &str,
) -> Result<(), A::Error> {
    use serde::de::Error as _;
    match seq.next_element::<serde::de::IgnoredAny>()? {
        None => Ok(()),
        Some(_) => Err(A::Error::custom(format_args!("{what} has extra elements"))),
    }
}

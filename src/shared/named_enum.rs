//! `FromStr` and `Display` for a field-less enum from its names, once: the
//! names a flag, a grid key or a JSON field takes, and the error that lists
//! them when a name is unknown.

/// `named_enum!(Type, "what it is", Type::A => "a", Type::B => "b")`.
macro_rules! named_enum {
    ($ty:ty, $what:literal, $($variant:path => $name:literal),+) => {
        impl std::str::FromStr for $ty {
            type Err = String;

            fn from_str(name: &str) -> Result<Self, Self::Err> {
                match name {
                    $($name => Ok($variant),)+
                    other => Err(format!(
                        concat!("unknown ", $what, " {:?}: use ", $crate::shared::named_enum!(@list $($name),+)),
                        other
                    )),
                }
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(match self {
                    $($variant => $name,)+
                })
            }
        }
    };
    (@list $first:literal $(, $rest:literal)*) => { concat!($first $(, " or ", $rest)*) };
}

pub(crate) use named_enum;

//! Values known by name: on command lines, in manifests and in reports. Each name is written
//! once, in the type's [`Named::name`]; parsing, printing and the lists of names in messages are
//! derived from it and from [`Named::all`], so that a new variant cannot be forgotten in one of
//! them. Serde goes through the same names (`format::by_name` in the library).

use std::fmt;

/// A type whose values each have one name.
pub trait Named: Copy + 'static {
    /// What a value is, in messages (`layout`, `mode`).
    const WHAT: &'static str;

    /// Every value, in the order their names are listed.
    fn all() -> &'static [Self];

    /// The value's name.
    fn name(self) -> &'static str;
}

/// The value named `s`, or a message listing every name.
pub fn parse_name<T: Named>(s: &str) -> Result<T, String> {
    T::all()
        .iter()
        .copied()
        .find(|v| v.name() == s)
        .ok_or_else(|| format!("unknown {} {} (expected {})", T::WHAT, quoted(s), names::<T>()))
}

/// Text a user gave, quoted for a one-line message: `'…'`, control characters escaped and
/// anything past 60 characters left out (a URL may carry kilobytes of it).
pub fn quoted(s: &str) -> String {
    const SHOWN: usize = 60;
    let mut out: String = s.chars().take(SHOWN).flat_map(char::escape_debug).collect();
    if s.chars().nth(SHOWN).is_some() {
        out.push('…');
    }
    format!("'{out}'")
}

/// Every name of `T`, as a list for messages: `a, b or c`.
pub fn names<T: Named>() -> String {
    let all: Vec<&str> = T::all().iter().map(|v| v.name()).collect();
    match all.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => all.concat(),
    }
}

/// Writes `v`'s name: the body of a `Display` that prints names.
pub fn write_name<T: Named>(v: T, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    f.write_str(v.name())
}

/// Makes `$t` a [`Named`] type from its inherent `ALL` and `name`, where its names are written
/// once.
#[macro_export]
macro_rules! named {
    ($t:ty, $what:literal) => {
        impl $crate::names::Named for $t {
            const WHAT: &'static str = $what;

            fn all() -> &'static [Self] {
                &<$t>::ALL
            }

            fn name(self) -> &'static str {
                <$t>::name(self)
            }
        }
    };
}

/// `Display` and `FromStr` (errors as `String`) of a [`Named`] type, by its names.
#[macro_export]
macro_rules! by_names {
    ($t:ty) => {
        impl ::std::fmt::Display for $t {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                $crate::names::write_name(*self, f)
            }
        }

        impl ::std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> ::std::result::Result<Self, String> {
                $crate::names::parse_name(s)
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Colour {
        Red,
        Light,
    }

    impl Named for Colour {
        const WHAT: &'static str = "colour";
        fn all() -> &'static [Self] {
            &[Colour::Red, Colour::Light]
        }
        fn name(self) -> &'static str {
            match self {
                Colour::Red => "red",
                Colour::Light => "light-blue",
            }
        }
    }

    by_names!(Colour);

    #[test]
    fn names_round_trip_and_messages_list_them_all() {
        for &c in Colour::all() {
            assert_eq!(c.to_string().parse::<Colour>().unwrap(), c);
        }
        assert_eq!("teal".parse::<Colour>().unwrap_err(), "unknown colour 'teal' (expected red or light-blue)");
        assert_eq!(names::<Colour>(), "red or light-blue");
    }
}

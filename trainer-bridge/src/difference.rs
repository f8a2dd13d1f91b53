//! The first field in which two sets of settings differ, named, with both values as text: what a
//! refusal to mix a dataset's, a DAgger part's or an evaluation shard's settings reports.
//!
//! [`FirstDifference`] compares the fields in the order given, each named once with how to read
//! it from either value, and keeps the first whose texts differ; fields after it are not
//! formatted.
//!
//! ```
//! use formation_trainer_bridge::difference::FirstDifference;
//!
//! struct Rollouts {
//!     seed: u64,
//!     team_sizes: Vec<usize>,
//! }
//! let (a, b) = (
//!     Rollouts { seed: 7, team_sizes: vec![3, 5] },
//!     Rollouts { seed: 7, team_sizes: vec![3, 8] },
//! );
//! let found = FirstDifference::of(&a, &b)
//!     .display("seed", |r| r.seed)
//!     .debug("team sizes", |r| &r.team_sizes)
//!     .found();
//! assert_eq!(found, Some(("team sizes", "[3, 5]".to_owned(), "[3, 8]".to_owned())));
//! ```

use std::fmt::{Debug, Display};

/// The first differing field, `(name, first value, second value)`.
pub type Difference = (&'static str, String, String);

/// Compares two values field by field and keeps the first field whose texts differ.
#[derive(Debug, Clone)]
#[must_use = "read the difference with `found`"]
pub struct FirstDifference<'a, T: ?Sized> {
    a: &'a T,
    b: &'a T,
    found: Option<Difference>,
}

impl<'a, T: ?Sized> FirstDifference<'a, T> {
    /// Compares `a` with `b`; no field compared yet.
    pub fn of(a: &'a T, b: &'a T) -> Self {
        FirstDifference { a, b, found: None }
    }

    /// Starts from a difference found elsewhere (say, in a nested header): when it is `Some`,
    /// the fields compared after it are not.
    pub fn after(mut self, found: Option<Difference>) -> Self {
        self.found = self.found.or(found);
        self
    }

    /// Compares the field `value` reads by its `Display` text.
    pub fn display<V: Display>(self, field: &'static str, value: impl Fn(&'a T) -> V) -> Self {
        self.compare(field, |x| value(x).to_string())
    }

    /// Compares the field `value` reads by its `Debug` text.
    pub fn debug<V: Debug>(self, field: &'static str, value: impl Fn(&'a T) -> V) -> Self {
        self.compare(field, |x| format!("{:?}", value(x)))
    }

    fn compare(mut self, field: &'static str, text: impl Fn(&'a T) -> String) -> Self {
        if self.found.is_none() {
            let (a, b) = (text(self.a), text(self.b));
            if a != b {
                self.found = Some((field, a, b));
            }
        }
        self
    }

    /// The first field that differed, if any.
    pub fn found(self) -> Option<Difference> {
        self.found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_differing_field_is_kept_and_the_later_ones_are_not_formatted() {
        struct Panics;
        impl Display for Panics {
            fn fmt(&self, _: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                panic!("formatted a field after the first difference")
            }
        }
        let (a, b) = (("x", 1.5, [1]), ("x", 2.0, [2]));
        let found = FirstDifference::of(&a, &b)
            .display("same", |t| t.0)
            .display("v_train", |t| t.1)
            .debug("later", |t| t.2)
            .display("never", |_| Panics)
            .found();
        assert_eq!(found, Some(("v_train", "1.5".to_owned(), "2".to_owned())));
        assert_eq!(
            FirstDifference::of(&a, &a).debug("all", |t| t).found(),
            None
        );
        let nested = Some(("inner", "a".to_owned(), "b".to_owned()));
        assert_eq!(
            FirstDifference::of(&a, &b)
                .after(nested.clone())
                .display("outer", |t| t.1)
                .found(),
            nested
        );
    }
}

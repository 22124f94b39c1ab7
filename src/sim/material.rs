//! Batches of material and their A/B ratio category, which the advanced line's ratio sensor
//! reports and its sorting modes are matched against.

use serde::{Deserialize, Serialize};

use super::round::round2;

/// Integer units of material A and B in one place of the line (input, belt, sorting machine).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Batch {
    pub a: u32,
    pub b: u32,
}

impl Batch {
    pub const fn new(a: u32, b: u32) -> Self {
        Batch { a, b }
    }

    pub const fn total(self) -> u32 {
        self.a + self.b
    }

    /// Occupancy of a belt section holding this batch: `(A + B) / 100`.
    pub fn occupancy(self) -> f64 {
        f64::from(self.total()) / 100.0
    }

    /// A/B rounded to two decimals, and 3.0 when there is no B (the reference's convention).
    pub fn ratio(self) -> f64 {
        if self.b == 0 {
            3.0
        } else {
            round2(f64::from(self.a) / f64::from(self.b))
        }
    }

    /// The ratio category: positive (A-rich) at ratio >= 3, negative (B-rich) at <= 1/3.
    pub fn category(self) -> Category {
        let ratio = self.ratio();
        if ratio >= 3.0 {
            Category::Positive
        } else if ratio <= 1.0 / 3.0 {
            Category::Negative
        } else {
            Category::Basic
        }
    }
}

/// What the ratio sensor reports about a batch. The numbers are the wire values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Category {
    /// Neither material dominates (1/3 < A/B < 3).
    #[default]
    Basic = 0,
    /// A-rich: A/B >= 3.
    Positive = 1,
    /// B-rich: A/B <= 1/3.
    Negative = 2,
}

/// The sorting machine's mode (advanced line). A mode helps when it matches the category of the
/// batch it sorts and hurts otherwise; the numbers are the wire values, equal to the matching
/// category's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SortMode {
    #[default]
    Basic = 0,
    Positive = 1,
    Negative = 2,
}

pub const CATEGORIES: [Category; 3] = [Category::Basic, Category::Positive, Category::Negative];
pub const SORT_MODES: [SortMode; 3] = [SortMode::Basic, SortMode::Positive, SortMode::Negative];

impl Category {
    pub fn from_index(i: u8) -> Option<Self> {
        CATEGORIES.get(usize::from(i)).copied()
    }
    pub fn index(self) -> usize {
        self as usize
    }
}

impl SortMode {
    pub fn from_index(i: u8) -> Option<Self> {
        SORT_MODES.get(usize::from(i)).copied()
    }
    pub fn index(self) -> usize {
        self as usize
    }
    /// What the mode is for, as the node's scene and the Python dashboard and reports label it:
    /// its name, with the batches it is made for.
    pub fn label(self) -> &'static str {
        match self {
            SortMode::Basic => "basic",
            SortMode::Positive => "positive (A-rich)",
            SortMode::Negative => "negative (B-rich)",
        }
    }
    /// The mode made for batches of this category.
    pub fn for_category(category: Category) -> Self {
        SORT_MODES[category.index()]
    }
    pub fn matches(self, category: Category) -> bool {
        self.index() == category.index()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn categories_follow_the_reference_thresholds() {
        assert_eq!(Batch::new(30, 10).category(), Category::Positive); // exactly 3
        assert_eq!(Batch::new(29, 10).category(), Category::Basic);
        assert_eq!(Batch::new(10, 30).category(), Category::Negative); // 0.33 <= 1/3
        assert_eq!(Batch::new(10, 29).category(), Category::Basic); // 0.34
        assert_eq!(Batch::new(5, 0).category(), Category::Positive);
        assert_eq!(Batch::new(0, 0).category(), Category::Positive); // B == 0 counts as ratio 3
        assert_eq!(Batch::new(0, 7).category(), Category::Negative);
        assert_eq!(Batch::new(30, 50).category(), Category::Basic);
    }

    /// Each label starts with the mode's own name (`trace`, parameter files): one naming, not two.
    #[test]
    fn mode_labels_start_with_the_modes_names() {
        for m in SORT_MODES {
            let name = serde_json::to_value(m).unwrap();
            assert!(m.label().starts_with(name.as_str().unwrap()), "{m:?}: {}", m.label());
        }
    }

    #[test]
    fn modes_match_their_own_category_only() {
        for m in SORT_MODES {
            for c in CATEGORIES {
                assert_eq!(m.matches(c), m.index() == c.index());
            }
        }
    }
}

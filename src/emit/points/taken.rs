//! The points' names given so far, in one string: a program of 100,000 points holds no
//! allocation per name, and frees none when it is done.

use std::hash::BuildHasher as _;

/// A set of names, their bytes kept one after another in `text`.
pub(super) struct Names {
    text: String,
    /// Each name's hash (kept: growing the table hashes no name again) and its place in `text`.
    table: hashbrown::HashTable<(u64, usize, usize)>,
    /// A random key, as `std`'s maps: step names cannot be chosen to collide.
    state: foldhash::fast::RandomState,
}

impl Names {
    pub fn new() -> Self {
        Names {
            text: String::new(),
            table: hashbrown::HashTable::new(),
            state: foldhash::fast::RandomState::default(),
        }
    }

    /// Room for `n` more names (of about 16 bytes).
    pub fn reserve(&mut self, n: usize) {
        self.table.reserve(n, |&(h, ..)| h);
        self.text.reserve(n.saturating_mul(16));
    }

    pub fn contains(&self, name: &str) -> bool {
        let hash = self.state.hash_one(name);
        self.table
            .find(hash, |&(h, a, b)| h == hash && &self.text[a..b] == name)
            .is_some()
    }

    /// Adds `name`; false when it was there already.
    pub fn insert(&mut self, name: &str) -> bool {
        let hash = self.state.hash_one(name);
        let text = &self.text;
        match self.table.entry(
            hash,
            |&(h, a, b)| h == hash && &text[a..b] == name,
            |&(h, ..)| h,
        ) {
            hashbrown::hash_table::Entry::Occupied(_) => false,
            hashbrown::hash_table::Entry::Vacant(v) => {
                let start = self.text.len();
                self.text.push_str(name);
                v.insert((hash, start, self.text.len()));
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Names;

    #[test]
    fn a_name_is_found_once_added_and_only_then() {
        let mut names = Names::new();
        names.reserve(2);
        assert!(!names.contains("pick"));
        assert!(names.insert("pick"));
        assert!(!names.insert("pick"));
        assert!(names.contains("pick"));
        // A name that is the start or end of another is not it.
        assert!(!names.contains("pic"));
        assert!(!names.contains("ick"));
        assert!(!names.contains(""));
        // Past the room reserved: the table grows, every name still found.
        for i in 0..10_000 {
            assert!(names.insert(&format!("p{i}")));
        }
        for i in 0..10_000 {
            assert!(names.contains(&format!("p{i}")), "p{i}");
        }
        assert!(!names.contains("p10000"));
        assert!(names.contains("pick"));
    }
}

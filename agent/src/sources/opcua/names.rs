//! The tags' names in one string, for messages.

use crate::tags::TagConfig;

/// The tags' names, for messages, in one string: a tag costs its name's
/// bytes and one `u32`.
#[derive(Debug, Default)]
pub struct Names {
    text: String,
    /// Name `t` is `text[ends[t - 1]..ends[t]]` (from 0 for the first).
    ends: Vec<u32>,
}

impl Names {
    /// The names of `tags`.
    pub(crate) fn of(tags: &[TagConfig]) -> Names {
        let mut names = Names {
            text: String::with_capacity(tags.iter().map(|t| t.name.len()).sum()),
            ends: Vec::with_capacity(tags.len()),
        };
        for t in tags {
            names.text.push_str(&t.name);
            names.ends.push(names.text.len() as u32);
        }
        names
    }
}

impl std::ops::Index<usize> for Names {
    type Output = str;

    fn index(&self, tag: usize) -> &str {
        let from = tag.checked_sub(1).map_or(0, |p| self.ends[p] as usize);
        &self.text[from..self.ends[tag] as usize]
    }
}

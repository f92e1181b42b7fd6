//! A start tag's attributes as the reader picks them: the few names it wants of a tag, their
//! values unescaped into the element's scratch text with their places in the file.

use super::Stream;
use super::element::{Tagged, Val};
use crate::diag::{Diagnostic, Span};
use crate::model::Name;
use crate::read::tape;

/// The bytes that make an attribute's raw value differ from its value (a reference, or white
/// space the XML rules turn into a space): such a value is normalized, any other copied.
const NOT_PLAIN: [bool; 256] = {
    let mut t = [false; 256];
    t[b'&' as usize] = true;
    t[b'\t' as usize] = true;
    t[b'\n' as usize] = true;
    t[b'\r' as usize] = true;
    t
};

impl Stream {
    /// The `name` attribute as a [`Name`]; `None` when it is missing or blank.
    pub(super) fn name_attr(
        &mut self,
        t: &Tagged,
        scratch: &mut String,
    ) -> Result<Option<Name>, Box<Diagnostic>> {
        let mark = scratch.len();
        let [n] = self.pick(t, ["name"], scratch)?;
        let name = n
            .map(|a| {
                self.names
                    .name(a.get(scratch), Span::new(self.file, a.range.clone()))
            })
            .filter(|n| !n.key.is_empty());
        scratch.truncate(mark);
        Ok(name)
    }

    /// The attributes named `names` (local names), in that order, their values appended to
    /// `scratch`; others are skipped (not unescaped).
    pub(super) fn pick<const N: usize>(
        &self,
        t: &Tagged,
        names: [&str; N],
        scratch: &mut String,
    ) -> Result<[Option<Val>; N], Box<Diagnostic>> {
        let mark = scratch.len();
        let mut out: [Option<Val>; N] = std::array::from_fn(|_| None);
        let content: &str = &t.e;
        let name_len = t.e.name().as_ref().len();
        let quick = tape::each_attribute(content, name_len, |key, raw| {
            self.take(t, key, raw, &names, &mut out, scratch)
        });
        if let Some(done) = quick {
            return done.map(|()| out);
        }
        // Not read there: quick-xml's iterator, for its words about the error.
        scratch.truncate(mark);
        let mut out: [Option<Val>; N] = std::array::from_fn(|_| None);
        for a in t.e.attributes() {
            let a = a.map_err(|err| self.syntax_error(t.at, err.to_string()))?;
            self.take(t, a.key.as_ref(), &a.value, &names, &mut out, scratch)?;
        }
        Ok(out)
    }

    /// One attribute for [`Self::pick`]: its value appended to `scratch` and put in `out` when
    /// its local name is one of `names` and not given before.
    fn take<const N: usize>(
        &self,
        t: &Tagged,
        key: &str,
        raw: &str,
        names: &[&str; N],
        out: &mut [Option<Val>; N],
        scratch: &mut String,
    ) -> Result<(), Box<Diagnostic>> {
        let local = tape::local_part(key);
        let Some(slot) = names.iter().position(|n| *n == local) else {
            return Ok(());
        };
        if out[slot].is_some() {
            return Ok(());
        }
        let raw_at = t.offset_of(raw, t.at);
        let range = raw_at..raw_at + raw.len();
        let start = scratch.len();
        // (A byte loop with a table: a search for any of several `char`s goes a character at
        // a time, `memchr` costs more for values this short.)
        let plain = !raw.bytes().any(|c| NOT_PLAIN[usize::from(c)]);
        let exact = if plain {
            scratch.push_str(raw);
            true
        } else {
            let attr = quick_xml::events::attributes::Attribute {
                key: quick_xml::name::QName(key),
                value: std::borrow::Cow::Borrowed(raw),
            };
            let v = attr
                .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                .map_err(|err| self.syntax_error(raw_at, err.to_string()))?;
            scratch.push_str(&v);
            v.len() == range.len()
        };
        out[slot] = Some(Val {
            at: start..scratch.len(),
            range,
            exact,
        });
        Ok(())
    }
}

//! A tag's attributes, read where quick-xml would read them without an error.

use quick_xml::utils::is_whitespace;

/// The bytes that end an attribute's name: `=` and XML white space (quick-xml's
/// `is_whitespace`), looked up in one step (the names are most of the bytes scanned).
const ENDS_NAME: [bool; 256] = {
    let mut t = [false; 256];
    let mut c = 0;
    while c < 256 {
        t[c] = c == b'=' as usize || is_whitespace(c as u8);
        c += 1;
    }
    t
};

/// The attributes of a tag's `content` after its name (which ends at `from`), each handed to
/// `each` as `(qualified name, raw value)`, in order, as quick-xml's attribute iterator gives
/// them, without its per-attribute state machine.
///
/// `None` where that iterator would report an error (a name without `=` or a value, a value
/// without quotes or its closing quote, a name given twice), and for a tag of more than 16
/// attributes: the caller reads the tag again with quick-xml, for its words. `each` may have
/// been called for the attributes before. An error from `each` ends the reading.
pub(crate) fn each_attribute<'a, E>(
    content: &'a str,
    from: usize,
    mut each: impl FnMut(&'a str, &'a str) -> Result<(), E>,
) -> Option<Result<(), E>> {
    let b = content.as_bytes();
    let mut keys = [(0usize, 0usize); 16];
    let mut n = 0;
    let mut i = from;
    loop {
        while i < b.len() && is_whitespace(b[i]) {
            i += 1;
        }
        if i >= b.len() {
            return Some(Ok(()));
        }
        let key = i;
        // The first byte is the name's, whatever it is (as in quick-xml).
        i += 1;
        i += b[i..]
            .iter()
            .position(|&c| ENDS_NAME[usize::from(c)])
            .unwrap_or(b.len() - i);
        let key_end = i;
        while i < b.len() && is_whitespace(b[i]) {
            i += 1;
        }
        if b.get(i) != Some(&b'=') {
            return None;
        }
        i += 1;
        while i < b.len() && is_whitespace(b[i]) {
            i += 1;
        }
        let quote = *b.get(i).filter(|&&q| q == b'"' || q == b'\'')?;
        let value = i + 1;
        let value_end = value + memchr::memchr(quote, b.get(value..)?)?;
        let name = &b[key..key_end];
        if n == keys.len() || keys[..n].iter().any(|&(s, e)| &b[s..e] == name) {
            return None;
        }
        keys[n] = (key, key_end);
        n += 1;
        // Every bound is at an ASCII byte or the end: a character boundary.
        if let Err(e) = each(&content[key..key_end], &content[value..value_end]) {
            return Some(Err(e));
        }
        i = value_end + 1;
    }
}

/// [`each_attribute`] beside quick-xml's iterator over the same tag content (for the tests and
/// the fuzz target): `Err` with both lists where they differ; a tag [`each_attribute`] leaves
/// to quick-xml must be one quick-xml reports an error for, or has more than 16 attributes.
#[doc(hidden)]
pub fn compare_attributes(content: &str) -> Result<(), String> {
    let name_len = content
        .bytes()
        .position(|c| is_whitespace(c) || c == b'/')
        .unwrap_or(content.len());
    let e = quick_xml::events::BytesStart::from_content(content, name_len);
    let mut theirs = Vec::new();
    let mut their_error = None;
    for a in e.attributes() {
        match a {
            Ok(a) => {
                let key: &str = a.key.as_ref();
                theirs.push((key.to_owned(), a.value.to_string()));
            }
            Err(err) => {
                their_error = Some(err.to_string());
                break;
            }
        }
    }
    let mut ours = Vec::new();
    let read = each_attribute(content, name_len, |k, v| {
        ours.push((k.to_owned(), v.to_owned()));
        Ok::<(), ()>(())
    });
    match (read, their_error) {
        (Some(_), None) if ours == theirs => Ok(()),
        (None, Some(_)) => Ok(()),
        (None, None) if theirs.len() > 16 => Ok(()),
        (read, err) => Err(format!(
            "{content:?}: here {read:?} {ours:?}, quick-xml {err:?} {theirs:?}"
        )),
    }
}

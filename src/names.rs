//! Name matching: every name the program looks up is compared case-insensitively after trimming
//! (German umlauts and ß included), and KRL names are validated here.

/// The comparison key of a name: trimmed and lower-cased (Unicode, so `Ä` and `ä` are one letter).
pub fn key(name: &str) -> String {
    let t = name.trim();
    if t.is_ascii() {
        // The same as `to_lowercase` for ASCII, without its per-`char` path.
        t.to_ascii_lowercase()
    } else {
        t.to_lowercase()
    }
}

/// How many single-character edits (insert, delete, replace; case ignored) turn `a` into `b`.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = key(a).chars().collect();
    let b: Vec<char> = key(b).chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let up = row[j + 1];
            row[j + 1] = (up + 1).min(row[j] + 1).min(diag + usize::from(ca != cb));
            diag = up;
        }
    }
    row[b.len()]
}

/// The candidate nearest to `name` for a "did you mean" (case ignored): at most two edits away
/// and fewer edits than half of `name`'s letters (`R2 Weldng` finds `R2 Welding`, `x` finds
/// nothing), or else the only candidate that contains `name` or is contained in it, both of 3
/// letters or more (`Weld` finds `R2 Weld`). Ties go to the first. `None` when nothing is near, or `name`
/// itself is a candidate.
pub fn closest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let k = key(name);
    let n = k.chars().count();
    if n == 0 {
        return None;
    }
    let mut best: Option<(usize, &'a str)> = None;
    let mut containing: Vec<&'a str> = Vec::new();
    for c in candidates {
        let ck = key(c);
        if ck == k {
            return None;
        }
        // Far longer or shorter names cannot be two edits away.
        if ck.chars().count().abs_diff(n) <= 2 {
            let d = edit_distance(&k, &ck);
            if d <= 2 && 2 * d < n && best.is_none_or(|(b, _)| d < b) {
                best = Some((d, c));
            }
        }
        if n >= 3 && (ck.contains(&k) || (ck.len() >= 3 && k.contains(&ck))) {
            containing.push(c);
        }
    }
    match (best, containing.as_slice()) {
        (Some((_, c)), _) => Some(c),
        (None, [one]) => Some(one),
        _ => None,
    }
}

/// `; did you mean `X`?` for [`closest`], or nothing.
pub fn did_you_mean<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    closest(name, candidates).map_or(String::new(), |c| format!("; did you mean `{c}`?"))
}

/// Whether two names are the same under [`key`].
pub fn eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.trim(), b.trim());
    if a.is_ascii() && b.is_ascii() {
        a.eq_ignore_ascii_case(b)
    } else {
        a.to_lowercase() == b.to_lowercase()
    }
}

/// Whether `name` is a valid KRL name: a letter or `_`, then letters, digits or `_`, at most 24
/// characters.
pub fn is_krl_name(name: &str) -> bool {
    let b = name.as_bytes();
    !b.is_empty()
        && b.len() <= 24
        && (b[0].is_ascii_alphabetic() || b[0] == b'_')
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

/// Makes a KRL name of any text (a folder or file name): transliterated like a comment
/// (`Ü` → `Ue`), every other character that is not a letter, digit or `_` replaced by `_`, `_`
/// put before a leading digit, cut to 24 characters, `_` after a KRL keyword (`End` → `End_`,
/// which `DEF` accepts). A KRL name that is not a keyword comes back unchanged.
pub fn to_krl_name(text: &str) -> String {
    let mut name: String = transliterate(text)
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if !name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        name.insert(0, '_');
    }
    name.truncate(24);
    if is_krl_keyword(&name) {
        name.push('_');
    }
    name
}

/// KRL keywords that cannot name a signal (compared case-insensitively). Upper-case and sorted
/// by bytes: [`is_krl_keyword`] searches it (held by a test).
const KRL_KEYWORDS: &[&str] = &[
    "AND",
    "ANIN",
    "ANOUT",
    "BOOL",
    "BRAKE",
    "B_AND",
    "B_EXOR",
    "B_NOT",
    "B_OR",
    "CASE",
    "CAST_FROM",
    "CAST_TO",
    "CHAR",
    "CIRC",
    "CIRC_REL",
    "CONST",
    "CONTINUE",
    "DECL",
    "DEF",
    "DEFAULT",
    "DEFDAT",
    "DEFFCT",
    "DELAY",
    "DO",
    "ELSE",
    "END",
    "ENDDAT",
    "ENDFCT",
    "ENDFOR",
    "ENDIF",
    "ENDLOOP",
    "ENDSWITCH",
    "ENDWHILE",
    "ENUM",
    "EXIT",
    "EXOR",
    "EXT",
    "EXTFCT",
    "FALSE",
    "FOR",
    "GLOBAL",
    "GOTO",
    "HALT",
    "IF",
    "IMPORT",
    "INT",
    "INTERRUPT",
    "IS",
    "LIN",
    "LIN_REL",
    "LOOP",
    "MAXIMUM",
    "MINIMUM",
    "NOT",
    "OR",
    "PRIO",
    "PTP",
    "PTP_REL",
    "PUBLIC",
    "PULSE",
    "REAL",
    "REPEAT",
    "RESUME",
    "RETURN",
    "SEC",
    "SIGNAL",
    "STRUC",
    "SWITCH",
    "THEN",
    "TO",
    "TRIGGER",
    "TRUE",
    "UNTIL",
    "WAIT",
    "WHEN",
    "WHILE",
];

/// Whether `name` is a KRL keyword.
pub fn is_krl_keyword(name: &str) -> bool {
    // Upper-cased on the stack and looked up in the list, which is upper-case and sorted by
    // bytes (a point's name is tried against it for each of 100,000 steps).
    // Keywords are letters and `_` (a point's name with a digit is none: 100,000 of them).
    if !name.bytes().all(|b| b.is_ascii_alphabetic() || b == b'_') {
        return false;
    }
    let mut buf = [0u8; 32];
    let Some(upper) = buf.get_mut(..name.len()) else {
        return false;
    };
    upper.copy_from_slice(name.as_bytes());
    upper.make_ascii_uppercase();
    KRL_KEYWORDS
        .binary_search_by(|k| k.as_bytes().cmp(upper))
        .is_ok()
}

/// Transliterates text for a KRL comment: German umlauts and ß spelled out, other non-ASCII
/// letters reduced to their base letter where known, anything else `?`. Control characters
/// (line breaks) become spaces so a comment stays one line.
pub fn transliterate(text: &str) -> String {
    // Printable ASCII stays as it is (most text: copied whole).
    if text.bytes().all(|b| (0x20..0x7f).contains(&b)) {
        return text.to_owned();
    }
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_ascii() {
            out.push(if c.is_ascii_control() { ' ' } else { c });
            continue;
        }
        let s = match c {
            'ä' => "ae",
            'ö' => "oe",
            'ü' => "ue",
            'Ä' => "Ae",
            'Ö' => "Oe",
            'Ü' => "Ue",
            'ß' => "ss",
            'ẞ' => "SS",
            'à' | 'á' | 'â' | 'ã' | 'å' => "a",
            'À' | 'Á' | 'Â' | 'Ã' | 'Å' => "A",
            'è' | 'é' | 'ê' | 'ë' => "e",
            'È' | 'É' | 'Ê' | 'Ë' => "E",
            'ì' | 'í' | 'î' | 'ï' => "i",
            'Ì' | 'Í' | 'Î' | 'Ï' => "I",
            'ò' | 'ó' | 'ô' | 'õ' | 'ø' => "o",
            'Ò' | 'Ó' | 'Ô' | 'Õ' | 'Ø' => "O",
            'ù' | 'ú' | 'û' => "u",
            'Ù' | 'Ú' | 'Û' => "U",
            'ç' => "c",
            'Ç' => "C",
            'ñ' => "n",
            'Ñ' => "N",
            'æ' => "ae",
            'Æ' => "AE",
            'œ' => "oe",
            'Œ' => "OE",
            '\u{a0}' => " ",
            '°' => "deg",
            'µ' => "u",
            _ => "?",
        };
        out.push_str(s);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_krl_keywords_are_upper_case_and_sorted() {
        assert!(
            KRL_KEYWORDS
                .iter()
                .all(|k| k.bytes().all(|b| !b.is_ascii_lowercase()))
        );
        // `is_krl_keyword` rejects a name with anything else at once.
        assert!(
            KRL_KEYWORDS
                .iter()
                .all(|k| k.bytes().all(|b| b.is_ascii_uppercase() || b == b'_'))
        );
        assert!(
            KRL_KEYWORDS
                .windows(2)
                .all(|w| w[0].as_bytes() < w[1].as_bytes())
        );
        assert!(is_krl_keyword("b_and") && is_krl_keyword("Wait") && !is_krl_keyword("Weld"));
    }

    #[test]
    fn the_nearest_name_is_suggested_only_when_it_is_near() {
        let steps = ["PickPart", "PlacePart", "Start", "End"];
        assert_eq!(closest("PickPrt", steps), Some("PickPart"));
        assert_eq!(closest("pickpart ", steps), None, "the name itself");
        assert_eq!(closest("Xyz", steps), None);
        assert_eq!(
            closest("En", steps),
            None,
            "one edit of two letters is too far"
        );
        let resources = ["R1 Handling", "R2 Welding", "Gripper G1"];
        assert_eq!(closest("R2 Weldng", resources), Some("R2 Welding"));
        assert_eq!(closest("Welding", resources), Some("R2 Welding"));
        assert_eq!(closest("R", resources), None);
        assert_eq!(
            closest("VariantB", ["More_Parts", "Variant_B"]),
            Some("Variant_B")
        );
        assert_eq!(
            did_you_mean("Skils", ["Skills"]),
            "; did you mean `Skills`?"
        );
        assert_eq!(did_you_mean("Foo", ["Skills"]), "");
    }

    #[test]
    fn keys_fold_case_and_umlauts() {
        assert_eq!(key("  Größe "), key("GRÖSSE".replace("SS", "ß").as_str()));
        assert!(eq("Ärger", "äRGER"));
        assert!(eq(" Move PTP", "move ptp "));
        assert!(!eq("Move PTP", "Move LIN"));
    }

    #[test]
    fn krl_names() {
        assert!(is_krl_name("output"));
        assert!(is_krl_name("_a1"));
        assert!(is_krl_name("abcdefghijklmnopqrstuvwx"));
        assert!(!is_krl_name("abcdefghijklmnopqrstuvwxy"));
        assert!(!is_krl_name("1abc"));
        assert!(!is_krl_name("a-b"));
        assert!(!is_krl_name(""));
        assert!(!is_krl_name("Zelle_Ä"));
    }

    #[test]
    fn krl_names_from_any_text() {
        for (text, name) in [
            ("Zelle_A", "Zelle_A"),
            ("Palletizing Cell", "Palletizing_Cell"),
            ("Zelle_Übergabe", "Zelle_Uebergabe"),
            ("2024-Linie.v2", "_2024_Linie_v2"),
            ("Loop", "Loop_"),
            ("end", "end_"),
            ("", "_"),
            ("日本", "__"),
            (
                "Schweißzelle Nord Halle 7 Linie 3",
                "Schweisszelle_Nord_Halle",
            ),
        ] {
            assert_eq!(to_krl_name(text), name, "{text}");
            assert!(is_krl_name(&to_krl_name(text)), "{text}");
        }
    }

    #[test]
    fn transliteration() {
        assert_eq!(transliterate("Schweißen Überkopf"), "Schweissen Ueberkopf");
        assert_eq!(transliterate("a\r\nb"), "a  b");
        // DEL is a control character too; printable ASCII stays.
        assert_eq!(transliterate("a\u{7f}b ~{}"), "a b ~{}");
    }
}

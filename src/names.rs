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

/// KRL keywords that cannot name a signal (compared case-insensitively).
const KRL_KEYWORDS: &[&str] = &[
    "AND",
    "ANIN",
    "ANOUT",
    "B_AND",
    "B_EXOR",
    "B_NOT",
    "B_OR",
    "BOOL",
    "BRAKE",
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
    "EXT",
    "EXTFCT",
    "EXOR",
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
    KRL_KEYWORDS.iter().any(|k| k.eq_ignore_ascii_case(name))
}

/// Transliterates text for a KRL comment: German umlauts and ß spelled out, other non-ASCII
/// letters reduced to their base letter where known, anything else `?`. Control characters
/// (line breaks) become spaces so a comment stays one line.
pub fn transliterate(text: &str) -> String {
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
    }
}

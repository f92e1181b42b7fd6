//! Unit tests of the condition language: precedence, literals, calls, error locations, spans
//! and types.

use super::*;

fn p(s: &str) -> Result<Expr, SyntaxError> {
    parse(s, &|o| o)
}

fn st(s: &str) -> String {
    p(s).unwrap().to_st()
}

#[test]
fn precedence_is_st() {
    assert_eq!(st("a OR b AND c"), "a OR (b AND c)");
    assert_eq!(st("a AND b OR c"), "(a AND b) OR c");
    assert_eq!(st("a XOR b OR c AND d"), "(a XOR b) OR (c AND d)");
    assert_eq!(st("n = 3 AND m < 2"), "(n = 3) AND (m < 2)");
    assert_eq!(st("a = b < c"), "a = (b < c)");
    assert_eq!(st("NOT a AND b"), "(NOT a) AND b");
    assert_eq!(st("NOT (a AND b)"), "NOT (a AND b)");
    assert_eq!(st("a & b & c"), "(a AND b) AND c");
    assert_eq!(st("- n < -3"), "(-n) < (-3)");
    assert_eq!(st(" ((TRUE)) "), "TRUE");
    assert_eq!(st("x >= 1.5 (* a comment *)"), "x >= 1.5");
    assert!(p("true").unwrap().is_true());
    assert!(p("not FALSE").is_ok());
}

/// TIME literals (IEC 61131-3): units from days to nanoseconds, `_` between components, a
/// fraction on the last; rendered in milliseconds for listings.
#[test]
fn time_literals_are_read() {
    assert_eq!(st("S.t > T#350ms"), "S.t > T#350ms");
    assert_eq!(st("S.t > t#1h1m"), "S.t > T#3660000ms");
    assert_eq!(st("S.t >= TIME#1s_500ms"), "S.t >= T#1500ms");
    assert_eq!(st("S.t > T#0.35S"), "S.t > T#350ms");
    assert_eq!(st("S.t > LT#1d"), "S.t > T#86400000ms");
    assert_eq!(st("S.t > T#1us"), "S.t > T#0.001ms");
    assert_eq!(st("S.t > T#+2s"), "S.t > T#2000ms");
    let e = |s: &str| p(s).unwrap_err().message;
    assert!(e("S.t > T#5").contains("not a unit"), "{}", e("S.t > T#5"));
    assert!(e("S.t > T#5x").contains("not a unit"));
    assert!(e("S.t > T#-5s").contains("never negative"));
    assert!(e("S.t > T#1s1m").contains("days down to"));
    assert!(e("S.t > T#1.5s2ms").contains("last unit"));
    assert!(e("S.t > T#s").contains("a number and a unit"));
    assert!(e("S.t > T#99999999999d").contains("too long"));
    // Times compare with times only.
    let ty = |s: &str| {
        check(&p(s).unwrap(), &|n| (n == "S.t").then_some(Ty::Time))
            .into_iter()
            .map(|e| e.message)
            .collect::<Vec<_>>()
    };
    assert!(ty("S.t > T#1s").is_empty());
    assert!(ty("T#1s < S.t AND S.t <> T#2s").is_empty());
    assert!(!ty("S.t > 5").is_empty());
    assert!(!ty("S.t AND TRUE").is_empty());
    assert!(!ty("-S.t < T#1s").is_empty());
}

/// Standard functions called in ST, as the blocks of a wired condition; `expr;` as a
/// statement.
#[test]
fn function_calls_are_read() {
    assert_eq!(st("AND(a, b, c)"), "(a AND b) AND c");
    assert_eq!(st("OR(a, NOT b)"), "a OR (NOT b)");
    assert_eq!(st("xor(a, b)"), "a XOR b");
    assert_eq!(st("GT(n, 2)"), "n > 2");
    assert_eq!(st("GE(a, b, c)"), "(a >= b) AND (b >= c)");
    assert_eq!(st("SEL(g, a, b)"), "(g AND b) OR ((NOT g) AND a)");
    assert_eq!(st("MOVE(a) AND NOT(b)"), "a AND (NOT b)");
    assert_eq!(st("AND(EQ(n, 1), b)"), "(n = 1) AND b");
    assert_eq!(
        st("GT(ADD(n, 2, m), MUL(n, 3))"),
        "ADD(ADD(n, 2), m) > MUL(n, 3)"
    );
    assert_eq!(st("SUB(n, 1) = 0"), "SUB(n, 1) = 0");
    assert_eq!(
        render_krl(&p("GT(SUB(n, 1), 2)").unwrap(), &|n| n.to_owned()),
        "(n - 1) > 2"
    );
    assert!(
        !check(&p("ADD(a, 1) AND b").unwrap(), &|_| Some(Ty::Bool)).is_empty(),
        "arithmetic of booleans"
    );
    assert!(check(&p("ADD(a, 1) > b").unwrap(), &|_| Some(Ty::Number)).is_empty());
    assert!(p("SUB(a, b, c)").unwrap_err().message.contains("takes 2"));
    assert_eq!(st("a = b;"), "a = b");
    assert_eq!(st("a ; (* done *)"), "a");
    let e = |s: &str| p(s).unwrap_err().message;
    assert!(e("TON(a, b)").contains("not part of the condition language"));
    assert!(e("AND(a)").contains("at least 2"));
    assert!(e("SEL(a, b)").contains("takes 3"));
    assert!(e("AND(a, b").contains("without its `)`"));
    assert!(e("AND(a b)").contains("`,` or `)`"));
    assert!(e("a; b").contains("one expression"));
}

/// IEC 61131-3 literals (docs/INPUTS.md): `1`/`0` as booleans where a boolean belongs, `BOOL#1`,
/// typed and based literals, `_` between digits; written in decimal.
#[test]
fn iec_literals_are_read() {
    assert!(p("1").unwrap().is_true());
    assert_eq!(st("0"), "FALSE");
    assert_eq!(st("BOOL#1 AND BOOL#FALSE"), "TRUE AND FALSE");
    assert_eq!(st("NOT 0"), "NOT FALSE");
    assert_eq!(st("a AND 1"), "a AND TRUE");
    assert_eq!(st("(n > 2) = 1"), "(n > 2) = TRUE");
    // A number where a number belongs stays one.
    assert_eq!(st("n = 1"), "n = 1");
    assert_eq!(st("n >= 1"), "n >= 1");
    assert_eq!(st("n = 16#FF"), "n = 255");
    assert_eq!(st("n = 2#1010 OR n = 8#17"), "(n = 10) OR (n = 15)");
    assert_eq!(st("n = INT#-5"), "n = (-5)");
    assert_eq!(st("n = DINT#16#1_0"), "n = 16");
    assert_eq!(st("n < 1_000"), "n < 1000");
    assert_eq!(st("x > REAL#1.5"), "x > 1.5");
    assert_eq!(st("x > LREAL#2"), "x > 2.0");
    assert_eq!(st("n = 007"), "n = 7");
    let e = |s: &str| p(s).unwrap_err().message;
    assert!(e("n = 3#12").contains("base"), "{}", e("n = 3#12"));
    assert!(e("n = 16#").contains("digits of its base"));
    assert!(e("n = 1__0").contains("between digits"));
    assert!(e("n = 1_").contains("between digits"));
    assert!(e("BOOL#2").contains("not a BOOL literal"));
    assert!(e("t > STRING#5").contains("not part of the condition language"));
    assert!(e("n = INT#1.5").contains("fraction"));
    assert!(e("n = 16#1_0000_0000").contains("larger than a KRL integer"));
}

/// Short texts of the characters literals are made of never make the reader panic, and an
/// error's place is always within the text.
#[test]
fn literal_like_texts_never_panic() {
    let alphabet: Vec<char> = "01279#_.-+ABFTxü€ (INT#BOOL#)".chars().collect();
    // Found by the fuzzer: a typed literal followed by a letter of two bytes.
    for t in [
        "BOOL#ö",
        "BOOL#öx",
        "INT#ö",
        "16#ö",
        "REAL#ü",
        "1_ö",
        "2#ö",
        "BOOL#\u{f6}rUng\u{0}\u{0}\u{0}\u{0}\u{0}\u{0}\u{0}\u{4}\u{4}\u{4}\u{4}\u{4}\u{4}L#F\u{6}\u{4}\u{4}\u{4}6\u{0}\u{0}\u{0}\u{0}\u{0}\u{4}\u{4}1S T",
    ] {
        if let Err(e) = p(t) {
            assert!(
                t.is_char_boundary(e.at.start) && t.is_char_boundary(e.at.end),
                "{t:?}"
            );
        }
    }
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for _ in 0..50_000 {
        let mut t = String::new();
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        for k in 0..(x % 9) {
            t.push(alphabet[((x >> (k * 5)) % alphabet.len() as u64) as usize]);
        }
        match p(&t) {
            Err(e) => assert!(
                e.at.end <= t.len()
                    && t.is_char_boundary(e.at.start)
                    && t.is_char_boundary(e.at.end),
                "{t:?}: {e:?}"
            ),
            // Printed back as ST, it reads the same (the fuzz target's round trip).
            Ok(e) => {
                let printed = e.to_st();
                assert_eq!(p(&printed).map(|x| x.to_st()), Ok(printed), "{t:?}");
            }
        }
    }
}

#[test]
fn krl_keeps_the_meaning() {
    let sig = |n: &str| match n {
        "a" => "$IN[1]".to_owned(),
        "b" => "$IN[2]".to_owned(),
        other => other.to_ascii_uppercase(),
    };
    let k = |s: &str| render_krl(&p(s).unwrap(), &sig);
    // ST: `n = 3 AND a` is `(n = 3) AND a`; KRL would read `N == (3 AND $IN[1])`.
    assert_eq!(k("n = 3 AND a"), "(N == 3) AND $IN[1]");
    assert_eq!(k("a XOR b"), "$IN[1] EXOR $IN[2]");
    assert_eq!(k("n <> 2"), "N <> 2");
    assert_eq!(k("NOT a OR b"), "(NOT $IN[1]) OR $IN[2]");
    assert_eq!(k("a = b"), "$IN[1] == $IN[2]");
}

#[test]
fn syntax_errors_are_located() {
    let e = |s: &str| p(s).unwrap_err();
    assert_eq!(e("a AND").at, 4..5);
    assert!(e("a AND").message.contains("ends where an operand"));
    assert_eq!(e("a b").at, 2..3);
    assert!(e("a b").message.contains("operator is missing"));
    assert_eq!(e("(a OR b").at, 0..1);
    assert_eq!(
        st("Robot.Ready AND NOT GVL.Door_Open"),
        "Robot.Ready AND (NOT GVL.Door_Open)"
    );
    assert_eq!(e("Robot.5").at, 5..6);
    assert_eq!(e("Robot.").at, 5..6);
    assert!(e("%IX0.1").message.contains("direct addresses"));
    assert_eq!(e("a := 1").at, 2..3);
    assert_eq!(e("  ").at, 0..2);
    assert_eq!(e("3a").at, 0..2);
    assert_eq!(e("a AND )").at, 6..7);
    assert!(e("(* open").message.contains("`*)`"));
    assert!(
        e("n = 2147483648")
            .message
            .contains("larger than a KRL integer")
    );
    assert!(p("n = 2147483647").is_ok());
    // Unicode letters are letters of names (docs/INPUTS.md); other characters are not.
    assert_eq!(st("Störung AND Grüße"), "Störung AND Grüße");
    assert!(e("a € b").message.contains("`€`"));
    let deep = format!("{}a{}", "(".repeat(100), ")".repeat(100));
    assert!(e(&deep).message.contains("deeper"));
    let nots = format!("{}a", "NOT ".repeat(100));
    assert!(e(&nots).message.contains("deeper"));
    let long = vec!["a"; 600].join(" AND ");
    assert!(e(&long).message.contains("longer than 1024 tokens"));
    let fine = vec!["a"; 500].join(" OR ");
    assert!(p(&fine).is_ok());
}

#[test]
fn spans_follow_the_map() {
    let e = parse("a OR b", &|o| o + 100).unwrap();
    assert_eq!(e.span, 100..106);
    assert_eq!(e.names(), vec![("a", 100..101), ("b", 105..106)]);
}

#[test]
fn types() {
    let look = |n: &str| match n {
        "a" | "b" => Some(Ty::Bool),
        "n" => Some(Ty::Number),
        _ => None,
    };
    let c = |s: &str| check(&p(s).unwrap(), &look);
    assert!(c("a AND NOT b OR n = 3").is_empty());
    assert!(c("n <> -2 XOR a").is_empty());
    let e = c("n AND a");
    assert_eq!(e.len(), 1);
    assert!(e[0].message.contains("needs a boolean"), "{e:?}");
    assert!(
        c("a = 3")[0]
            .message
            .contains("compares a boolean with a number")
    );
    assert!(c("n")[0].message.contains("not a boolean"));
    assert!(c("a < b")[0].message.contains("needs a number"));
    let u = c("x OR y");
    assert_eq!(u.len(), 2);
    assert!(u[0].unknown && u[0].message == "x");
}

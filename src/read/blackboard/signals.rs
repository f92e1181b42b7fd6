//! A resource's signals (`SignalInterface`/`Channel` interfaces): bits, groups and addresses,
//! with their checks (`MAX_IO`, `is_safe_address`).

use roxmltree::Node;

use super::super::xml::{caex_attr, caex_element, caex_value, children};
use super::{Reader, internal_element, ref_base_ends_with};
use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::{Signal, SignalKind, ValueType};
use crate::names;

/// The highest I/O index a signal may use (KRL's `$IN`/`$OUT` have 4096 on a KR C4; 8192 on
/// later controllers).
pub const MAX_IO: u32 = 8192;

/// An `Address` is one safe token: a name or a `$`system variable, optionally with one or two
/// integer indexes (`PART_OK`, `$IN[5]`, `$CYCFLAG[3]`, `$X[1,2]`).
pub fn is_safe_address(s: &str) -> bool {
    // A call with one integer argument (URScript: `read_input_integer_register(2)`).
    if let Some(inner) = s.strip_suffix(')')
        && let Some((f, arg)) = inner.split_once('(')
    {
        return crate::value::is_ident(f)
            && f.len() <= 63
            && !arg.is_empty()
            && arg.len() <= 9
            && arg.bytes().all(|b| b.is_ascii_digit());
    }
    let (base, index) = match s.find('[') {
        Some(i) => (&s[..i], Some(&s[i..])),
        None => (s, None),
    };
    let name = base.strip_prefix('$').unwrap_or(base);
    let ident = !name.is_empty()
        && name.len() <= 24
        && (name.as_bytes()[0].is_ascii_alphabetic() || name.as_bytes()[0] == b'_')
        && name.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_');
    let index_ok = match index {
        None => true,
        Some(ix) => ix
            .strip_prefix('[')
            .and_then(|r| r.strip_suffix(']'))
            .is_some_and(|inner| {
                let parts: Vec<&str> = inner.split(',').collect();
                parts.len() <= 2
                    && parts.iter().all(|p| {
                        !p.is_empty() && p.len() <= 9 && p.bytes().all(|b| b.is_ascii_digit())
                    })
            }),
    };
    ident && index_ok && !names::is_krl_keyword(name)
}

impl Reader<'_> {
    /// The resource's signals: `ExternalInterface`s directly under it or under its child named
    /// `Signals`/`Signale` whose `RefBaseClassPath` ends in `SignalInterface` or `Channel`.
    pub(super) fn signals(&mut self, r: Node) -> (Vec<Signal>, Vec<std::sync::Arc<str>>) {
        let mut ifaces: Vec<Node> = children(r, "ExternalInterface").collect();
        if let Some(group) = internal_element(r, &["Signals", "Signale"]) {
            ifaces.extend(children(group, "ExternalInterface"));
        }
        let mut signals = Vec::new();
        let mut broken = Vec::new();
        for ei in ifaces {
            if !(ref_base_ends_with(ei, "SignalInterface") || ref_base_ends_with(ei, "Channel")) {
                continue;
            }
            match self.signal(ei) {
                Some(s) => signals.push(s),
                None => broken.push(self.name_of(ei).key),
            }
        }
        self.check_unique(
            signals.iter().map(|s| (&s.name, s.element.as_str())),
            "signal",
        );
        (signals, broken)
    }

    fn signal(&mut self, ei: Node) -> Option<Signal> {
        let name = self.name_of(ei);
        let element = caex_element(ei);
        let mut ok = true;
        let value = |attr: &str| {
            caex_attr(ei, attr)
                .and_then(|a| caex_value(self.file, a))
                .filter(|(v, _)| !v.is_empty())
        };
        let mut bad = |diags: &mut Diagnostics, span: Span, msg: String| {
            diags.push(
                Diagnostic::error(Code::BadSignal, format!("signal `{}`: {msg}", name.text))
                    .at(span)
                    .element(element.clone()),
            );
            ok = false;
        };
        let output = match value("IoType") {
            None => false,
            Some((v, span)) => match v.to_ascii_lowercase().as_str() {
                "input" | "in" => false,
                "output" | "out" => true,
                _ => {
                    bad(
                        self.diags,
                        span,
                        format!("IoType `{v}` is neither `Input` nor `Output`"),
                    );
                    false
                }
            },
        };
        let integer = match value("Type") {
            None => false,
            Some((v, span)) => match ValueType::parse(&v) {
                Some(ValueType::Boolean) => false,
                Some(ValueType::Integer) => true,
                _ => {
                    bad(
                        self.diags,
                        span,
                        format!(
                            "Type `{v}` is neither `xs:boolean` (one bit) nor `xs:integer` (a group of `Length` bits)"
                        ),
                    );
                    false
                }
            },
        };
        let kind = if let Some((text, span)) = value("Address") {
            if !is_safe_address(&text) {
                bad(
                    self.diags,
                    span,
                    format!(
                        "Address `{text}` is not one safe token: write a name, a system variable with an index or a call with one number (`PART_OK`, `$IN[5]`, `di_Part`, `read_input_integer_register(2)`)"
                    ),
                );
            }
            SignalKind::Address { text, integer }
        } else {
            let number = match value("Number") {
                None => {
                    bad(
                        self.diags,
                        self.span(ei),
                        "no `Number` (the first I/O index, from 1) and no `Address`".to_owned(),
                    );
                    1
                }
                Some((v, span)) => match v.parse::<u32>() {
                    Ok(n) if (1..=MAX_IO).contains(&n) => n,
                    // URScript counts its standard digital I/O from 0; KRL refuses 0 where a
                    // program would use it (`E209`).
                    Ok(0) if !integer => 0,
                    Ok(0) => {
                        bad(
                            self.diags,
                            span,
                            "Number 0 cannot start a group: KRL counts inputs and outputs from 1 ($IN[1])".to_owned(),
                        );
                        1
                    }
                    _ => {
                        bad(
                            self.diags,
                            span,
                            format!("Number `{v}` is not an I/O index from 1 to {MAX_IO}"),
                        );
                        1
                    }
                },
            };
            if integer {
                let length = match value("Length") {
                    None => {
                        bad(
                            self.diags,
                            self.span(ei),
                            "an xs:integer signal needs a `Length` (its number of bits, 2 to 32)"
                                .to_owned(),
                        );
                        2
                    }
                    Some((v, span)) => match v.parse::<u32>() {
                        Ok(l) if (2..=32).contains(&l) => {
                            if number.saturating_add(l - 1) > MAX_IO {
                                bad(
                                    self.diags,
                                    span,
                                    format!(
                                        "Length {l} from Number {number} passes the last I/O index {MAX_IO}"
                                    ),
                                );
                            }
                            l
                        }
                        _ => {
                            bad(
                                self.diags,
                                span,
                                format!("Length `{v}` is not a number of bits from 2 to 32"),
                            );
                            2
                        }
                    },
                };
                if !names::is_krl_name(&name.text)
                    || names::is_krl_keyword(&name.text)
                    || names::eq(&name.text, crate::lang::BRANCH_VAR)
                {
                    let span = name.span.clone();
                    bad(
                        self.diags,
                        span,
                        "an integer signal is declared as a KRL SIGNAL of this name: it must be a KRL name (a letter or `_`, then letters, digits or `_`, at most 24 characters, not a keyword nor `SKP_BRANCH`)".to_owned(),
                    );
                }
                SignalKind::Group { number, length }
            } else {
                SignalKind::Bit(number)
            }
        };
        ok.then_some(Signal {
            name,
            element,
            output,
            kind,
            holder: ei
                .parent_element()
                .and_then(|p| p.attribute("ID"))
                .map(|id| id.trim().to_owned()),
        })
    }
}

#[cfg(test)]
mod signal_tests {
    use super::is_safe_address;

    #[test]
    fn addresses_are_one_safe_token() {
        for ok in ["PART_OK", "$IN[5]", "$CYCFLAG[3]", "$X[1,2]", "_a1"] {
            assert!(is_safe_address(ok), "{ok}");
        }
        for bad in [
            "$IN[5]; $OUT[1]=TRUE",
            "$IN[ 5]",
            "$IN[]",
            "$IN[5",
            "a b",
            "1X",
            "$",
            "END",
            "$IN[1][2]",
            "$IN[-1]",
            "",
            "Grüße",
        ] {
            assert!(!is_safe_address(bad), "{bad}");
        }
    }
}

//! The statement forms of the handshakes in each robot language: how a wire is read and set
//! (KRL by its `SIGNAL` name), a wait (watched: a message on the pendant when it lasts), a
//! stop with its message, and KRL's routines for those messages. The protocol that uses them
//! (what is waited for, in which order) is in the parent module.

use super::*;
use std::borrow::Cow;

/// `text` with no quote or backslash (inside a string literal of any of the three languages).
pub(super) fn clean(t: &str) -> Cow<'_, str> {
    // Most texts have neither: taken as they are (every handshake cleans several).
    if memchr::memchr2(b'"', b'\\', t.as_bytes()).is_none() {
        return Cow::Borrowed(t);
    }
    t.chars()
        .map(|c| match c {
            '"' => '\'',
            '\\' => '/',
            c => c,
        })
        .collect::<String>()
        .into()
}

/// Besides URScript's keywords ([`crate::emit::urscript::KEYWORDS`]), the functions the
/// generated code calls: no wire is named so.
const UR_CALLED: &[&str] = &[
    "None",
    "p",
    "sync",
    "sleep",
    "popup",
    "textmsg",
    "movel",
    "movej",
    "movep",
    "movec",
    "servoj",
    "speedl",
    "speedj",
    "stopl",
    "stopj",
    "get_steptime",
    "get_standard_digital_in",
    "set_standard_digital_out",
    "get_standard_digital_out",
    "is_steady",
    "set_tcp",
    "set_payload",
];

/// A RAPID condition for `WaitUntil`: one of several parts in parentheses as a whole
/// (`rapidchecker` reads `WaitUntil (a) AND (b)` and `WaitUntil (c) \PollRate` as calls).
fn rapid_whole(cond: &str) -> std::borrow::Cow<'_, str> {
    if cond.starts_with('(') {
        format!("({cond})").into()
    } else {
        cond.into()
    }
}

/// A message for KRL's `Msg_Txt` and RAPID's lines (80 characters): `text`, or where it is
/// longer `short` (made only then), cut at 80; both cleaned.
pub(super) fn fit(text: Arguments, short: Arguments) -> String {
    let text = text.to_string();
    // At most 80 bytes is at most 80 characters: counted only when longer.
    if text.len() <= 80 || text.chars().count() <= 80 {
        return cleaned(text);
    }
    let short = cleaned(short.to_string());
    if short.len() <= 80 {
        return short;
    }
    short.chars().take(80).collect()
}

/// [`clean`] of a text of one's own: kept as it is when it needs no cleaning.
fn cleaned(text: String) -> String {
    match clean(&text) {
        Cow::Borrowed(_) => text,
        Cow::Owned(c) => c,
    }
}

/// Milliseconds as seconds, as short as the value allows (`10`, `0.05`).
pub(super) fn seconds(ms: u64) -> String {
    if ms.is_multiple_of(1000) {
        return (ms / 1000).to_string();
    }
    let s = format!("{}.{:03}", ms / 1000, ms % 1000);
    s.trim_end_matches('0').to_owned()
}

/// A KRL message number (`INT`, 32 bits) of a `localId`.
pub(super) fn message_nr(id: u64) -> u64 {
    id.min(i32::MAX as u64)
}

impl<'a> Hand<'a> {
    pub(super) fn comment(&self) -> &'static str {
        match self.lang {
            Language::Krl => ";",
            Language::Rapid => "! ",
            Language::UrScript => "# ",
        }
    }

    /// KRL and URScript: the names of the wires this program drives or reads on numbered I/O
    /// (inputs, then outputs, by number): each signal's name in the blackboard made a KRL name
    /// ([`crate::names::to_krl_name`], also a URScript name), unique in the program without
    /// regard to case (a number added), never one of the program's own (`skp_…` becomes
    /// `w_skp_…`) nor, in KRL, an integer signal's the conditions use, nor, in URScript, a
    /// keyword, a function the generated code calls or a word of the program's IRL code (a
    /// variable of a snippet that assigned a wire's name would change the wire silently).
    pub(super) fn name_wires(&self) -> Vec<(usize, String, String)> {
        let bb = self.input.blackboard;
        let mut taken: std::collections::HashSet<String> = std::collections::HashSet::new();
        match self.lang {
            Language::Krl => {
                if let Some(r) = self.input.bound.resource {
                    for &si in &self.input.bound.signals {
                        taken.insert(bb.resources[r].signals[si].name.text.to_ascii_lowercase());
                    }
                }
            }
            Language::UrScript => {
                taken.extend(
                    crate::emit::urscript::KEYWORDS
                        .iter()
                        .chain(UR_CALLED)
                        .map(|w| w.to_ascii_lowercase()),
                );
                let mut words = |text: &str| {
                    for w in text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
                        if !w.is_empty() {
                            taken.insert(w.to_ascii_lowercase());
                        }
                    }
                };
                for b in self.input.bound.steps.unordered() {
                    words(&b.code);
                }
                for &(i, d) in &self.input.bound.definitions {
                    for l in &self.input.irls[i].definitions[d].lines {
                        words(l);
                    }
                }
            }
            Language::Rapid => return Vec::new(),
        }
        // Inputs first, then outputs, each by number (the order of an I/O list): a lower number
        // keeps the plain name when two would be the same.
        let mut wires: Vec<(usize, &Signal, bool, u32)> = Vec::new();
        for (wire, side) in self.uses() {
            let Some(s) = self.signal(wire, side) else {
                continue;
            };
            let SignalKind::Bit(n) = s.kind else {
                continue;
            };
            if self.lang == Language::UrScript && n > 7 {
                continue;
            }
            let key = std::ptr::from_ref(s) as usize;
            if !wires.iter().any(|(k, ..)| *k == key) {
                wires.push((key, s, s.output, n));
            }
        }
        wires.sort_by_key(|&(_, _, output, n)| (output, n));
        let mut out = Vec::with_capacity(wires.len());
        for (key, s, output, n) in wires {
            let mut base = crate::names::to_krl_name(&s.name.text);
            // The program's own names begin with `skp_`: a wire's never does.
            if base.to_ascii_lowercase().starts_with("skp_") {
                base = crate::names::to_krl_name(&format!("w_{base}"));
            }
            let mut name = base.clone();
            let mut k = 1;
            while taken.contains(&name.to_ascii_lowercase()) {
                k += 1;
                let suffix = format!("_{k}");
                let keep = base.len().min(24 - suffix.len());
                name = format!("{}{suffix}", &base[..keep]);
            }
            taken.insert(name.to_ascii_lowercase());
            let address = match (self.lang, output) {
                (Language::Krl, true) => format!("$OUT[{n}]"),
                (Language::Krl, false) => format!("$IN[{n}]"),
                _ => n.to_string(),
            };
            out.push((key, name, address));
        }
        out
    }

    /// The wires this program uses: (wire, whether on the sender's side, whether it writes).
    pub(super) fn uses(&self) -> Vec<(Option<usize>, bool)> {
        let me = self.view.me;
        let mut uses = Vec::new();
        for l in &self.view.cell.links {
            if l.from == me {
                uses.extend([(l.run, true), (l.ready, true)]);
            }
            if l.to == me {
                uses.extend([(l.run, false), (l.ready, false)]);
            }
        }
        for ch in &self.view.cell.channels {
            if ch.from == me {
                uses.push((ch.strobe, true));
                uses.extend(ch.data.iter().map(|&w| (Some(w), true)));
                uses.push((ch.ack, false));
            }
            if ch.to == me {
                uses.push((ch.strobe, false));
                uses.extend(ch.data.iter().map(|&w| (Some(w), false)));
                uses.push((ch.ack, true));
            }
        }
        uses
    }

    /// KRL and URScript: the name a numbered wire goes by ([`Hand::name_wires`]).
    pub(super) fn wire_named(&self, s: &Signal) -> Option<&str> {
        let key = std::ptr::from_ref(s) as usize;
        self.names_of_wires
            .iter()
            .find(|(k, _, _)| *k == key)
            .map(|(_, n, _)| n.as_str())
    }

    /// A numbered wire in the program: its name ([`Hand::name_wires`]), else `number()`.
    fn bit(&self, s: &Signal, number: impl FnOnce() -> String) -> String {
        self.wire_named(s).map_or_else(number, str::to_owned)
    }

    /// How this language reads an input wire as a boolean value.
    pub(super) fn read(&self, s: &Signal) -> Result<String, String> {
        match (self.lang, &s.kind) {
            (Language::Krl, SignalKind::Bit(0)) => Err(crate::emit::krl::NUMBER_0.to_owned()),
            (Language::Krl, SignalKind::Bit(n)) => Ok(self.bit(s, || format!("$IN[{n}]"))),
            (Language::Krl, SignalKind::Address { text, .. }) if !text.contains('(') => {
                Ok(text.clone())
            }
            (
                Language::Rapid,
                SignalKind::Address {
                    text,
                    integer: false,
                },
            ) => Ok(format!("DInput({text})")),
            (Language::UrScript, SignalKind::Bit(n)) if *n <= 7 => Ok(format!(
                "get_standard_digital_in({})",
                self.bit(s, || n.to_string())
            )),
            (Language::UrScript, SignalKind::Address { text, .. })
                if !text.starts_with('$') && !text.contains('[') =>
            {
                Ok(text.clone())
            }
            _ => Err(self.cannot("read")),
        }
    }

    /// How this language sets an output wire to `value` (a boolean expression).
    pub(super) fn set(&self, s: &Signal, value: &str) -> Result<String, String> {
        match (self.lang, &s.kind) {
            (Language::Krl, SignalKind::Bit(0)) => Err(crate::emit::krl::NUMBER_0.to_owned()),
            (Language::Krl, SignalKind::Bit(n)) => Ok(format!(
                "{} = {value}",
                self.bit(s, || format!("$OUT[{n}]"))
            )),
            (Language::Krl, SignalKind::Address { text, .. })
                if !text.contains('(') && !text.contains("$IN") =>
            {
                Ok(format!("{text} = {value}"))
            }
            (
                Language::Rapid,
                SignalKind::Address {
                    text,
                    integer: false,
                },
            ) => Ok(format!("SetDO {text}, {value};")),
            (Language::UrScript, SignalKind::Bit(n)) if *n <= 7 => Ok(format!(
                "set_standard_digital_out({}, {value})",
                self.bit(s, || n.to_string())
            )),
            _ => Err(self.cannot("write")),
        }
    }

    pub(super) fn cannot(&self, what: &str) -> String {
        match self.lang {
            Language::Krl => format!(
                "KRL cannot {what} this wire: give it a `Number` (`$IN[n]`/`$OUT[n]`) or an `Address` that is a BOOL name or system variable"
            ),
            Language::Rapid => format!(
                "RAPID cannot {what} this wire: give it an `Address` with the digital signal's configured name (`do_Ready`, `di_Ready`)"
            ),
            Language::UrScript => format!(
                "URScript cannot {what} this wire: give it a `Number` of the standard digital I/O (0 to 7){}",
                if what == "read" {
                    " or an `Address` call (`read_input_boolean_register(3)`)"
                } else {
                    ""
                }
            ),
        }
    }

    pub(super) fn t(&self) -> &'static str {
        match self.lang {
            Language::Krl => "TRUE",
            Language::Rapid => "1",
            Language::UrScript => "True",
        }
    }

    pub(super) fn f(&self) -> &'static str {
        match self.lang {
            Language::Krl => "FALSE",
            Language::Rapid => "0",
            Language::UrScript => "False",
        }
    }

    pub(super) fn assign(&self, var: &str, value: &str) -> String {
        match self.lang {
            Language::Krl => format!("{var} = {value}"),
            Language::Rapid => format!("{var} := {value};"),
            Language::UrScript => format!("{var} = {value}"),
        }
    }

    /// The line that toggles `var`.
    pub(super) fn toggle(&self, out: &mut At, var: &str) {
        match self.lang {
            Language::Krl => out.put(0, format_args!("{var} = NOT {var}")),
            Language::Rapid => out.put(0, format_args!("{var} := 1 - {var};")),
            Language::UrScript => out.put(0, format_args!("{var} = not {var}")),
        }
    }

    /// A wire read as "is `level`" (an atom of a condition).
    pub(super) fn is(&self, read: &str, level: bool) -> String {
        match (self.lang, level) {
            (Language::Krl, true) => read.to_owned(),
            (Language::Krl, false) => format!("NOT {read}"),
            (Language::Rapid, true) => format!("{read} = 1"),
            (Language::Rapid, false) => format!("{read} = 0"),
            (Language::UrScript, true) => read.to_owned(),
            (Language::UrScript, false) => format!("not {read}"),
        }
    }

    /// A wire read as "equals `var`" (a toggle).
    pub(super) fn equals(&self, read: &str, var: &str) -> String {
        match self.lang {
            Language::Krl | Language::UrScript => format!("{read} == {var}"),
            Language::Rapid => format!("{read} = {var}"),
        }
    }

    /// `parts` joined by `op` (`"AND"`/`"OR"`), each in parentheses when there are several
    /// (KRL compares last: `a == b AND c` is `a == (b AND c)`).
    pub(super) fn join(&self, op: &str, parts: &[String]) -> String {
        if parts.len() == 1 {
            return parts[0].clone();
        }
        let op = match self.lang {
            Language::UrScript => op.to_ascii_lowercase(),
            _ => op.to_owned(),
        };
        parts
            .iter()
            .map(|p| format!("({p})"))
            .collect::<Vec<_>>()
            .join(&format!(" {op} "))
    }

    /// A wait until `cond` holds, once the motions before have ended: KRL's `WAIT FOR` stops
    /// the advance run, RAPID's `\InPos` waits for the robot to stand, URScript's moves return
    /// at their target.
    pub(super) fn wait_until(&self, out: &mut At, cond: Arguments) {
        match self.lang {
            Language::Krl => out.put(0, format_args!("WAIT FOR {cond}")),
            Language::Rapid => {
                // `\InPos` also where the robot stands anyway, and a condition of several
                // parts in parentheses as a whole: `rapidchecker` reads `WaitUntil (a) AND (b)`
                // and `WaitUntil (c) \PollRate` as calls.
                let pos = "\\InPos, ";
                let cond = cond.to_string();
                out.put(
                    0,
                    format_args!(
                        "WaitUntil {pos}{} {};",
                        rapid_whole(&cond),
                        crate::emit::rapid::POLL_RATE
                    ),
                );
            }
            // URScript's `movel`/`movej` return when the motion has ended (as for the chart's
            // own waits; an IRL that blends leaves that to its own code): no `is_steady()`,
            // which turns true only after 0.5 s of standstill and never in force mode.
            Language::UrScript => {
                out.put(0, format_args!("while not ({cond}):"));
                out.line(1, "sync()");
                out.line(0, "end");
            }
        }
    }

    /// A wait on a partner: [`Hand::wait_until`] `cond`, and when it lasts longer than the
    /// controller's `HandshakeTimeout` ([`crate::bind::Watch`]), a message on the pendant
    /// saying what the program waits for (`text`, or where a message is short `short`), taken
    /// away when the wait ends; the program goes on waiting. Each vendor's own way: KUKA's wait
    /// message (`Set_KrlMsg(#WAITING)`, cleared by `Clr_KrlMsg`), RAPID's `\MaxTime`
    /// `\TimeFlag` with `TPWrite` (cleared by `TPErase`), URScript's `textmsg` in the log at
    /// the start and the end of the long wait.
    pub(super) fn watched_wait(
        &self,
        out: &mut At,
        cond: &str,
        text: Arguments,
        short: Arguments,
        nr: u64,
    ) {
        let Some(w) = self.input.bound.watch else {
            return self.wait_until(out, format_args!("{cond}"));
        };
        let after = seconds(w.after_ms);
        match self.lang {
            // The program's routines (see `routines`) start the timer, show and clear the
            // message; the text goes into the message first.
            Language::Krl => {
                let t = w.timer;
                out.put(0, format_args!("{WATCH}()"));
                out.put(
                    0,
                    format_args!("WAIT FOR ({cond}) OR ($TIMER[{t}] >= {})", w.after_ms),
                );
                out.put(0, format_args!("IF NOT ({cond}) THEN"));
                out.put(
                    1,
                    format_args!("{MSG_VAR}.Msg_Txt[] = \"{}\"", fit(text, short)),
                );
                out.put(1, format_args!("{SHOW}({})", message_nr(nr)));
                self.wait_inside(out, cond);
                out.put(1, format_args!("{HIDE}()"));
                out.line(0, "ENDIF");
            }
            Language::Rapid => {
                let poll = crate::emit::rapid::POLL_RATE;
                out.put(
                    0,
                    format_args!(
                        "WaitUntil \\InPos, {} \\MaxTime:={after} \\TimeFlag:={LATE_VAR} {poll};",
                        rapid_whole(cond)
                    ),
                );
                out.put(0, format_args!("IF {LATE_VAR} THEN"));
                out.put(1, format_args!("TPWrite \"{}\";", fit(text, short)));
                self.wait_inside(out, cond);
                out.line(1, "TPErase;");
                out.line(0, "ENDIF");
            }
            Language::UrScript => {
                let text = cleaned(text.to_string());
                out.put(0, format_args!("{WATCH_VAR} = 0.0"));
                // A number URScript reads as a float.
                let after = if after.contains('.') {
                    after
                } else {
                    format!("{after}.0")
                };
                self.wait_until(out, format_args!("({cond}) or ({WATCH_VAR} >= {after})"));
                out.put(0, format_args!("if not ({cond}):"));
                out.put(1, format_args!("textmsg(\"skillpost: {text}\")"));
                self.wait_inside(out, cond);
                out.put(
                    1,
                    format_args!("textmsg(\"skillpost: {text}: the wait has ended\")"),
                );
                out.line(0, "end");
            }
        }
    }

    /// [`Hand::wait_until`] one level deeper (the wait inside a watched wait's message block).
    fn wait_inside(&self, out: &mut At, cond: &str) {
        self.wait_until(&mut out.deeper(), format_args!("{cond}"));
    }

    /// `IF cond`: a message to the operator, and the program stops for good (until it is
    /// started again from its start).
    pub(super) fn stop_if(
        &self,
        out: &mut At,
        cond: &str,
        text: Arguments,
        short: Arguments,
        nr: u64,
        when: &str,
    ) {
        let c = self.comment();
        let end = match self.lang {
            Language::Krl | Language::Rapid => {
                out.put(0, format_args!("IF {cond} THEN"));
                "ENDIF"
            }
            Language::UrScript => {
                out.put(0, format_args!("if {cond}:"));
                "end"
            }
        };
        out.put(
            1,
            format_args!("{c}handshake: a partner was started again{when}: stop"),
        );
        match self.lang {
            // The text into the message, then the program's routine `skp_stop` (see
            // `routines`): KRL takes no string literal as an argument.
            Language::Krl => {
                out.put(
                    1,
                    format_args!("{MSG_VAR}.Msg_Txt[] = \"{}\"", fit(text, short)),
                );
                out.put(1, format_args!("{STOP}({})", message_nr(nr)));
            }
            Language::Rapid => {
                let short = fit(text, short);
                out.put(1, format_args!("ErrWrite \"Partner started again\", \"{short}\" \\RL2:=\"Start this task again from main.\";"));
                out.line(1, "EXIT;");
            }
            Language::UrScript => {
                let text = cleaned(text.to_string());
                out.put(1, format_args!("popup(\"{text}. Start this program again.\", title=\"skillpost\", error=True, blocking=False)"));
                out.line(1, "halt");
            }
        }
        out.line(0, end);
    }

    /// The routines the handshakes call, written after the program (KRL only: a message takes
    /// a structure, a call and a handle there, where RAPID and URScript need one statement).
    /// `skp_stop(nr)` shows `skp_msg` as an acknowledgement message and stops for good;
    /// `skp_watch()` starts the timer of a wait on a partner once the motion before has ended;
    /// `skp_show(nr)` shows `skp_msg` as a wait message, `skp_hide()` takes it away.
    pub fn routines(&self) -> Vec<String> {
        let (tx, rx) = self.own();
        if self.lang != Language::Krl || (tx.is_empty() && rx.is_empty()) {
            return Vec::new();
        }
        let mut out = vec![
            format!("DEF {STOP}(nr:IN)"),
            "  ;handshake: a partner was started again: the message in skp_msg (acknowledge), then stop until this program is started again".to_owned(),
            "  DECL INT nr".to_owned(),
            format!("  {MSG_VAR}.Nr = nr"),
            format!("  {HANDLE_VAR} = Set_KrlMsg(#QUIT, {MSG_VAR}, {PAR_VAR}[], {OPT_VAR})"),
            "  LOOP".to_owned(),
            "    HALT".to_owned(),
            "  ENDLOOP".to_owned(),
            "END".to_owned(),
        ];
        if let Some(w) = self.input.bound.watch {
            let t = w.timer;
            out.extend([
                String::new(),
                format!("DEF {WATCH}( )"),
                format!("  ;handshake: a wait on a partner begins: $TIMER[{t}] counts its milliseconds from when the motion before has ended (WAIT SEC 0 stops the advance run)"),
                "  WAIT SEC 0".to_owned(),
                format!("  $TIMER[{t}] = 0"),
                format!("  $TIMER_STOP[{t}] = FALSE"),
                "END".to_owned(),
                String::new(),
                format!("DEF {SHOW}(nr:IN)"),
                format!("  ;handshake: a wait on a partner lasts longer than {} s: the message in skp_msg (wait) until {HIDE}", seconds(w.after_ms)),
                "  DECL INT nr".to_owned(),
                format!("  {MSG_VAR}.Nr = nr"),
                format!("  {HANDLE_VAR} = Set_KrlMsg(#WAITING, {MSG_VAR}, {PAR_VAR}[], {OPT_VAR})"),
                "END".to_owned(),
                String::new(),
                format!("DEF {HIDE}( )"),
                "  ;handshake: the wait has ended: its message goes".to_owned(),
                format!("  {CLEARED_VAR} = Clr_KrlMsg({HANDLE_VAR})"),
                "END".to_owned(),
            ]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_cleaned_and_cut_at_80_characters() {
        assert_eq!(clean(r#"a "b" c\d"#), "a 'b' c/d");
        assert_eq!(clean("plain"), "plain");
        let long = "ä".repeat(50);
        // 100 bytes but 50 characters: whole.
        assert_eq!(fit(format_args!("{long}"), format_args!("short")), long);
        let longer = "x\"".repeat(50);
        assert_eq!(
            fit(format_args!("{longer}"), format_args!("the \"short\" one")),
            "the 'short' one"
        );
        let both = "é".repeat(100);
        assert_eq!(
            fit(format_args!("{both}"), format_args!("{both}"))
                .chars()
                .count(),
            80
        );
    }
}

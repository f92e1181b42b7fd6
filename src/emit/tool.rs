//! Tool, base and load of each step (docs/LANGUAGES.md, "Tool, base and load"): which of the
//! blackboard's tools, bases and loads a step uses, the statements that set them where they may
//! differ from the ones in effect, and `W211` for a resource whose steps move without them.
//!
//! **Which.** Each of tool, base and load is the step's resource's own; else, for a robot (a
//! resource that is its own controller), the one of the only device on it that has one; for a
//! device without one, its robot's by the same rule. The load is a resource's `Load`, or a
//! device's `Mass` (a robot's `Mass` is its own weight).
//!
//! **Where.** The writers put a step's statements at the top of the step ([`Tools::at`]). A
//! statement is written where what it sets may differ from what is in effect: a pass over the
//! program tree ([`Tools::new`]) follows what is in effect along a sequence, takes what all
//! branches of a selection agree on after it, and forgets everything at the head of a loop,
//! after a loop, at each state of flow beyond the structured forms and at each sequence of its
//! own. Without any tool, base or load in the program the output is what it was without them.

use std::collections::{HashMap, HashSet};

use super::EmitInput;
use crate::convert::{Conversion, format_number};
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::lang::Language;
use crate::model::{Blackboard, Frame, Resource};
use crate::names::transliterate;
use crate::plan::Block;

/// The statements of each step and the program's data.
#[derive(Debug, Default)]
pub struct Tools {
    /// Element index of a step → its statements, lines separated by `\n`.
    at: HashMap<usize, String>,
    /// The data the statements use (RAPID's `tooldata`/`wobjdata`, URScript's `skp_base`), one
    /// line each, written first in `{{definitions}}`.
    pub data: Vec<String>,
}

impl Tools {
    /// The statements that go at the top of step `i`, if any.
    pub fn at(&self, i: usize) -> Option<&str> {
        self.at.get(&i).map(String::as_str)
    }

    /// For KRL's inline forms, whose `FDAT` sets tool and base (and the tool's load) itself:
    /// `Ok(None)` when no step sets any, `Ok(Some((tool, base)))` when every statement is
    /// `BAS(#TOOL, n)` or `BAS(#BASE, m)` of one tool and one base (0: none), else the first
    /// statement an inline form would undo (`$TOOL = {…}`, `$LOAD = …`, a second tool).
    pub fn krl_numbers(&self) -> Result<Option<(u32, u32)>, String> {
        let mut steps: Vec<(&usize, &String)> = self.at.iter().collect();
        steps.sort();
        let (mut tool, mut base) = (None, None);
        for (_, lines) in steps {
            for l in lines.lines().filter(|l| !l.starts_with(';')) {
                let number = |what: &str| -> Option<u32> {
                    l.strip_prefix(&format!("BAS(#{what}, "))?
                        .strip_suffix(')')?
                        .trim()
                        .parse()
                        .ok()
                };
                let same = |seen: &mut Option<u32>, n: u32| *seen.get_or_insert(n) == n;
                match (number("TOOL"), number("BASE")) {
                    (Some(n), _) if same(&mut tool, n) => {}
                    (_, Some(m)) if same(&mut base, m) => {}
                    _ => return Err(l.to_owned()),
                }
            }
        }
        Ok((tool.is_some() || base.is_some()).then(|| (tool.unwrap_or(0), base.unwrap_or(0))))
    }

    /// Plans the statements of the program in `input`; `E217` for a numbered tool or base a
    /// language has no form for, `W211` for a resource whose steps move without tool, base or
    /// load.
    pub fn new(input: &EmitInput, diags: &mut Diagnostics) -> Tools {
        let bb = input.blackboard;
        if bb.resources.iter().all(|r| r.tooling.is_empty()) {
            // Nothing to set: the program is what it was, and each moving resource is warned of.
            warn_missing(input, &mut HashMap::new(), diags);
            return Tools::default();
        }
        let mut p = Planner {
            input,
            language: input.profile.language(),
            resolved: HashMap::new(),
            tools: Tools::default(),
            rapid_tools: Vec::new(),
            rapid_wobjs: Vec::new(),
            refused: HashSet::new(),
            diags,
        };
        let mut st = InEffect::default();
        p.walk(input.body, &mut st);
        let Planner {
            mut tools,
            rapid_tools,
            rapid_wobjs,
            mut resolved,
            diags,
            ..
        } = p;
        tools.data = data(input.profile.language(), &rapid_tools, &rapid_wobjs, &tools);
        warn_missing(input, &mut resolved, diags);
        tools
    }
}

/// What is in effect: the statement that set each of tool, base and load (`None`: not known).
#[derive(Debug, Default, Clone, PartialEq)]
struct InEffect {
    tool: Option<String>,
    base: Option<String>,
    load: Option<String>,
}

impl InEffect {
    /// What both agree on.
    fn meet(self, other: &InEffect) -> InEffect {
        let keep = |a: Option<String>, b: &Option<String>| a.filter(|a| Some(a) == b.as_ref());
        InEffect {
            tool: keep(self.tool, &other.tool),
            base: keep(self.base, &other.base),
            load: keep(self.load, &other.load),
        }
    }
}

/// A tool as a program sets it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ToolSel {
    /// One of the controller's own (KRL `TOOL_DATA[n]`, which brings `LOAD_DATA[n]`).
    Number(u8),
    Frame(Frame),
}

/// What a step of a resource uses, and from which resources.
#[derive(Debug, Clone, Default)]
struct Resolved {
    tool: Option<(ToolSel, usize)>,
    base: Option<(ToolSel, usize)>,
    load: Option<(crate::model::Load, usize)>,
    /// Devices that each have one where the robot has none (the choice is not made).
    several: Vec<(&'static str, Vec<usize>)>,
}

struct Planner<'a, 'd> {
    input: &'a EmitInput<'a>,
    language: Language,
    resolved: HashMap<usize, Resolved>,
    tools: Tools,
    /// RAPID: the distinct `tooldata` (frame, load) and `wobjdata` (frame) in order of use.
    rapid_tools: Vec<(Frame, Option<crate::model::Load>, String)>,
    rapid_wobjs: Vec<(Frame, String)>,
    /// Resources whose numbered tool or base was refused (`E217` once).
    refused: HashSet<(usize, &'static str)>,
    diags: &'d mut Diagnostics,
}

impl Planner<'_, '_> {
    fn walk(&mut self, blocks: &[Block], st: &mut InEffect) {
        for b in blocks {
            match b {
                Block::Step(i) => self.step(*i, st),
                Block::Wait(_) | Block::Tell(_) | Block::Hear(_) | Block::Goto { .. } => {}
                // On one robot, simultaneous branches run one after another.
                Block::Parallel { branches, .. } => {
                    for br in branches {
                        self.walk(br, st);
                    }
                }
                Block::Sequences(seqs) => {
                    for s in seqs {
                        *st = InEffect::default();
                        self.walk(s, st);
                    }
                    *st = InEffect::default();
                }
                Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
                    let before = st.clone();
                    let mut after: Option<InEffect> = None;
                    for br in branches {
                        let mut s = before.clone();
                        self.walk(&br.body, &mut s);
                        after = Some(match after {
                            None => s,
                            Some(a) => a.meet(&s),
                        });
                    }
                    *st = after.unwrap_or(before);
                }
                Block::Loop { body, .. } => {
                    *st = InEffect::default();
                    self.walk(body, st);
                    *st = InEffect::default();
                }
                Block::Machine(states) => {
                    for s in states {
                        *st = InEffect::default();
                        self.walk(&s.body, st);
                    }
                    *st = InEffect::default();
                }
            }
        }
    }

    fn step(&mut self, i: usize, st: &mut InEffect) {
        let Some(bs) = self.input.bound.steps.get(i) else {
            return;
        };
        let r = bs.resource;
        let res = self.resolve(r);
        let bb = self.input.blackboard;
        let name = |k: usize| transliterate(&bb.resources[k].name.text);
        let mut lines = Vec::new();
        let mut from: Vec<(&str, usize)> = Vec::new();
        let (tool, base, load) = self.statements(&res);
        if let Some((line, k)) = tool
            && st.tool.as_ref() != Some(&line)
        {
            if matches!(res.tool, Some((ToolSel::Number(_), _))) {
                // KRL's BAS(#TOOL, n) sets LOAD_DATA[n] as the load.
                st.load = None;
            }
            lines.push(line.clone());
            st.tool = Some(line);
            from.push(("tool", k));
        }
        if let Some((line, k)) = load
            && st.load.as_ref() != Some(&line)
        {
            lines.push(line.clone());
            st.load = Some(line);
            from.push(("load", k));
        }
        if let Some((line, k)) = base
            && st.base.as_ref() != Some(&line)
        {
            lines.push(line.clone());
            st.base = Some(line);
            from.push(("base", k));
        }
        if lines.is_empty() {
            return;
        }
        // A comment naming where each comes from: `tool and load of Gripper, base of Robot`.
        let mut parts: Vec<(Vec<&str>, usize)> = Vec::new();
        for (what, k) in from {
            match parts.iter_mut().find(|(_, kk)| *kk == k) {
                Some((ws, _)) => ws.push(what),
                None => parts.push((vec![what], k)),
            }
        }
        let said: Vec<String> = parts
            .iter()
            .map(|(ws, k)| format!("{} of {}", ws.join(" and "), name(*k)))
            .collect();
        let comment = match self.language {
            Language::Krl => ";",
            Language::Rapid => "! ",
            Language::UrScript => "# ",
        };
        lines.insert(0, format!("{comment}{}", said.join(", ")));
        self.tools.at.insert(i, lines.join("\n"));
    }

    /// The statements of a resolved tool, base and load, each with the resource it comes from.
    #[allow(clippy::type_complexity)]
    fn statements(
        &mut self,
        res: &Resolved,
    ) -> (
        Option<(String, usize)>,
        Option<(String, usize)>,
        Option<(String, usize)>,
    ) {
        match self.language {
            Language::Krl => (
                res.tool.map(|(t, k)| (krl_frame_or_number("TOOL", t), k)),
                res.base.map(|(b, k)| (krl_frame_or_number("BASE", b), k)),
                res.load.map(|(l, k)| {
                    let [x, y, z] = l.center.map(num);
                    (
                        format!(
                            "$LOAD = {{M {}, CM {{X {x}, Y {y}, Z {z}, A 0, B 0, C 0}}, J {{X 0, Y 0, Z 0}}}}",
                            num(l.mass)
                        ),
                        k,
                    )
                }),
            ),
            Language::Rapid => {
                // The tool's load is part of its tooldata.
                let tool = match (res.tool, res.load) {
                    (None, None) => None,
                    (t, l) => {
                        let frame = match t {
                            Some((ToolSel::Frame(f), _)) => f,
                            _ => ZERO,
                        };
                        let load = l.map(|(l, _)| l);
                        let k = t.map(|(_, k)| k).or(l.map(|(_, k)| k)).unwrap_or(0);
                        let n = match self
                            .rapid_tools
                            .iter()
                            .position(|(f, l, _)| *f == frame && *l == load)
                        {
                            Some(n) => n,
                            None => {
                                let what = match (t.is_some(), l.is_some()) {
                                    (true, true) => "tool and load",
                                    (true, false) => "tool",
                                    _ => "load",
                                };
                                let owner = self.input.blackboard.resources[k].name.text.clone();
                                self.rapid_tools.push((
                                    frame,
                                    load,
                                    format!("{what} of {}", transliterate(&owner)),
                                ));
                                self.rapid_tools.len() - 1
                            }
                        };
                        Some((format!("skp_tool := skp_tool{};", n + 1), k))
                    }
                };
                let base = match res.base {
                    Some((ToolSel::Frame(f), k)) => {
                        let n = match self.rapid_wobjs.iter().position(|(g, _)| *g == f) {
                            Some(n) => n,
                            None => {
                                let owner = &self.input.blackboard.resources[k].name.text;
                                self.rapid_wobjs
                                    .push((f, format!("base of {}", transliterate(owner))));
                                self.rapid_wobjs.len() - 1
                            }
                        };
                        Some((format!("skp_wobj := skp_wobj{};", n + 1), k))
                    }
                    _ => None,
                };
                (tool, base, None)
            }
            Language::UrScript => (
                match res.tool {
                    Some((ToolSel::Frame(f), k)) => Some((format!("set_tcp({})", ur_pose(f)), k)),
                    _ => None,
                },
                match res.base {
                    Some((ToolSel::Frame(f), k)) => Some((format!("skp_base = {}", ur_pose(f)), k)),
                    _ => None,
                },
                res.load.map(|(l, k)| {
                    let [x, y, z] = l.center.map(|c| num(c / 1000.0));
                    (format!("set_payload({}, [{x}, {y}, {z}])", num(l.mass)), k)
                }),
            ),
        }
    }

    /// What steps of resource `r` use (cached).
    fn resolve(&mut self, r: usize) -> Resolved {
        if let Some(res) = self.resolved.get(&r) {
            return res.clone();
        }
        let res = resolve(
            self.input.blackboard,
            r,
            self.language,
            &mut |k, what, span| {
                refuse(
                    self.language,
                    &mut self.refused,
                    self.diags,
                    self.input.blackboard,
                    k,
                    what,
                    span,
                )
            },
        );
        self.resolved.insert(r, res.clone());
        res
    }
}

const ZERO: Frame = Frame {
    xyz: [0.0; 3],
    abc: [0.0; 3],
};

/// A number as the programs write it (the values were range-checked when read).
fn num(x: f64) -> String {
    format_number(x).unwrap_or_else(|| "0".to_owned())
}

/// `$TOOL = {X 0, Y 0, Z 120, A 0, B 0, C 0}` or `BAS(#TOOL, 3)`.
fn krl_frame_or_number(var: &str, t: ToolSel) -> String {
    match t {
        ToolSel::Number(n) => format!("BAS(#{var}, {n})"),
        ToolSel::Frame(f) => format!("${var} = {}", krl_frame(f)),
    }
}

fn krl_frame(f: Frame) -> String {
    let [x, y, z] = f.xyz.map(num);
    let [a, b, c] = f.abc.map(num);
    format!("{{X {x}, Y {y}, Z {z}, A {a}, B {b}, C {c}}}")
}

/// RAPID's `[[x, y, z], [q1, q2, q3, q4]]` (mm, the unit quaternion).
fn rapid_pose(f: Frame) -> String {
    let [x, y, z] = f.xyz.map(num);
    let mut q = [0.0; 4];
    Conversion::Quat.apply(&f.abc, &mut q);
    let [w, qx, qy, qz] = q.map(num);
    format!("[[{x}, {y}, {z}], [{w}, {qx}, {qy}, {qz}]]")
}

/// URScript's `p[x, y, z, rx, ry, rz]` (m, the rotation vector in radians).
fn ur_pose(f: Frame) -> String {
    let [x, y, z] = f.xyz.map(|v| num(v / 1000.0));
    let mut r = [0.0; 4];
    Conversion::Rotvec.apply(&f.abc, &mut r);
    let [rx, ry, rz, _] = r.map(num);
    format!("p[{x}, {y}, {z}, {rx}, {ry}, {rz}]")
}

/// The data lines of a program: RAPID's `tooldata` and `wobjdata`, URScript's `skp_base`.
fn data(
    language: Language,
    rapid_tools: &[(Frame, Option<crate::model::Load>, String)],
    rapid_wobjs: &[(Frame, String)],
    tools: &Tools,
) -> Vec<String> {
    let mut out = Vec::new();
    match language {
        Language::Krl => {}
        Language::Rapid => {
            // tool0's and wobj0's values until a step sets them.
            let tool = |f: Frame, l: Option<crate::model::Load>| {
                let (m, c) = match l {
                    Some(l) => (num(l.mass), l.center.map(num)),
                    None => ("0.001".to_owned(), ["0", "0", "0.001"].map(str::to_owned)),
                };
                format!(
                    "[TRUE, {}, [{m}, [{}, {}, {}], [1, 0, 0, 0], 0, 0, 0]]",
                    rapid_pose(f),
                    c[0],
                    c[1],
                    c[2]
                )
            };
            let wobj = |f: Frame| {
                format!(
                    "[FALSE, TRUE, \"\", {}, [[0, 0, 0], [1, 0, 0, 0]]]",
                    rapid_pose(f)
                )
            };
            if !rapid_tools.is_empty() {
                out.push("! the tool the steps move with (skp_tool in the IRL's moves)".to_owned());
                out.push(format!("PERS tooldata skp_tool := {};", tool(ZERO, None)));
                for (n, (f, l, what)) in rapid_tools.iter().enumerate() {
                    out.push(format!("! {what}"));
                    out.push(format!(
                        "PERS tooldata skp_tool{} := {};",
                        n + 1,
                        tool(*f, *l)
                    ));
                }
            }
            if !rapid_wobjs.is_empty() {
                out.push(
                    "! the base the steps move in (\\WObj:=skp_wobj in the IRL's moves)".to_owned(),
                );
                out.push(format!("PERS wobjdata skp_wobj := {};", wobj(ZERO)));
                for (n, (f, what)) in rapid_wobjs.iter().enumerate() {
                    out.push(format!("! {what}"));
                    out.push(format!("PERS wobjdata skp_wobj{} := {};", n + 1, wobj(*f)));
                }
            }
        }
        Language::UrScript => {
            if tools.at.values().any(|s| s.contains("skp_base = ")) {
                out.push(
                    "# the base the steps move in (pose_trans(skp_base, p) in the IRL's moves)"
                        .to_owned(),
                );
                out.push(format!("skp_base = {}", ur_pose(ZERO)));
            }
        }
    }
    out
}

/// `E217` (once per resource and kind) for a numbered tool or base in a language without
/// numbered tools; `true` when it is refused.
fn refuse(
    language: Language,
    refused: &mut HashSet<(usize, &'static str)>,
    diags: &mut Diagnostics,
    bb: &Blackboard,
    k: usize,
    what: &'static str,
    span: crate::diag::Span,
) {
    if !refused.insert((k, what)) {
        return;
    }
    let (attr, frame) = match what {
        "tool" => ("ToolNumber", "Tool"),
        _ => ("BaseNumber", "Base"),
    };
    let r = &bb.resources[k];
    diags.push(
        Diagnostic::error(
            Code::BadToolData,
            format!(
                "resource `{}`: `{attr}` names one of a KUKA controller's own {what}s, which a {language} program cannot select: give the {what} as a frame, `{frame}`",
                r.name.text
            ),
        )
        .at(span)
        .element(r.element.clone()),
    );
}

/// The tool, base and load resource `r`'s steps use in `language`.
fn resolve(
    bb: &Blackboard,
    r: usize,
    language: Language,
    refuse: &mut dyn FnMut(usize, &'static str, crate::diag::Span),
) -> Resolved {
    let is_device = |k: usize| bb.controller_of(k) != k;
    let mut tool_of = |k: usize| -> Option<ToolSel> {
        let t = &bb.resources[k].tooling;
        match (language, t.tool_number.clone(), t.tool.clone()) {
            (Language::Krl, Some((n, _)), _) => Some(ToolSel::Number(n)),
            (_, _, Some((f, _))) => Some(ToolSel::Frame(f)),
            (_, Some((_, span)), None) => {
                refuse(k, "tool", span);
                None
            }
            _ => None,
        }
    };
    let tool = pick(bb, r, &mut tool_of);
    let mut base_of = |k: usize| -> Option<ToolSel> {
        let t = &bb.resources[k].tooling;
        match (language, t.base_number.clone(), t.base.clone()) {
            (Language::Krl, Some((n, _)), _) => Some(ToolSel::Number(n)),
            (_, _, Some((f, _))) => Some(ToolSel::Frame(f)),
            (_, Some((_, span)), None) => {
                refuse(k, "base", span);
                None
            }
            _ => None,
        }
    };
    let base = pick(bb, r, &mut base_of);
    let mut load_of = |k: usize| -> Option<crate::model::Load> {
        let t = &bb.resources[k].tooling;
        let mass = t
            .load
            .as_ref()
            .or(t.mass.as_ref().filter(|_| is_device(k)))
            .map(|(m, _)| *m)?;
        Some(crate::model::Load {
            mass,
            center: t.center.as_ref().map_or([0.0; 3], |(c, _)| *c),
        })
    };
    let load = pick(bb, r, &mut load_of);
    let mut several = Vec::new();
    for (what, p) in [
        ("tool", tool.as_ref().err()),
        ("base", base.as_ref().err()),
        ("load", load.as_ref().err()),
    ] {
        if let Some(ks) = p {
            several.push((what, ks.clone()));
        }
    }
    Resolved {
        tool: tool.ok().flatten(),
        base: base.ok().flatten(),
        load: load.ok().flatten(),
        several,
    }
}

/// Resource `r`'s own; else, for a robot, the only device's that has one; for a device, its
/// robot's by the same rule. `Err` with the devices when several have one and the robot none.
fn pick<T: Copy>(
    bb: &Blackboard,
    r: usize,
    own: &mut dyn FnMut(usize) -> Option<T>,
) -> Result<Option<(T, usize)>, Vec<usize>> {
    if let Some(t) = own(r) {
        return Ok(Some((t, r)));
    }
    let c = bb.controller_of(r);
    if c != r
        && let Some(t) = own(c)
    {
        return Ok(Some((t, c)));
    }
    let devices: Vec<(T, usize)> = (0..bb.resources.len())
        .filter(|&d| d != c && bb.controller_of(d) == c)
        .filter_map(|d| own(d).map(|t| (t, d)))
        .collect();
    match devices.len() {
        0 => Ok(None),
        1 => Ok(Some(devices[0])),
        _ => Err(devices.iter().map(|(_, d)| *d).collect()),
    }
}

/// Whether a line of a step's code moves the robot: its first word is a motion statement of
/// the language.
fn moves(language: Language, code: &str) -> bool {
    code.lines().any(|line| {
        let t = line.trim_start();
        let word: String = t
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        match language {
            Language::Krl => {
                let w = word.to_ascii_uppercase();
                let base = w.strip_suffix("_REL").unwrap_or(&w);
                matches!(
                    base,
                    "PTP" | "LIN" | "CIRC" | "SPTP" | "SLIN" | "SCIRC" | "SPLINE" | "PTP_SPLINE"
                )
            }
            Language::Rapid => {
                let w = word.to_ascii_lowercase();
                w.starts_with("move") || w.starts_with("search") || w.starts_with("trigg")
            }
            Language::UrScript => {
                matches!(
                    word.as_str(),
                    "movej"
                        | "movel"
                        | "movep"
                        | "movec"
                        | "servoj"
                        | "servoc"
                        | "speedj"
                        | "speedl"
                ) && t[word.len()..].trim_start().starts_with('(')
            }
        }
    })
}

/// `W211` once for each resource whose steps move and for which a tool, base or load is not
/// known, in the order of their first such step.
fn warn_missing(
    input: &EmitInput,
    resolved: &mut HashMap<usize, Resolved>,
    diags: &mut Diagnostics,
) {
    let bb = input.blackboard;
    let language = input.profile.language();
    let mut seen = HashSet::new();
    let mut order = Vec::new();
    // (The resource of the step before is looked up no further: a program's steps mostly run
    // on one resource, 100,000 of them.)
    let mut last = None;
    each_step(input.body, &mut |i| {
        let Some(bs) = input.bound.steps.get(i) else {
            return;
        };
        if last == Some(bs.resource) {
            return;
        }
        if seen.contains(&bs.resource) {
            last = Some(bs.resource);
        } else if moves(language, &bs.code) {
            seen.insert(bs.resource);
            order.push(bs.resource);
            last = Some(bs.resource);
        }
    });
    for r in order {
        let res = resolved
            .entry(r)
            .or_insert_with(|| resolve(bb, r, language, &mut |_, _, _| {}));
        // KRL's numbered tool brings its load (LOAD_DATA[n]).
        let load_known = res.load.is_some() || matches!(res.tool, Some((ToolSel::Number(_), _)));
        let missing: Vec<&str> = [
            (res.tool.is_none(), "tool (`Tool` or `ToolNumber`)"),
            (res.base.is_none(), "base (`Base` or `BaseNumber`)"),
            (!load_known, "load (`Load`, or a device's `Mass`)"),
        ]
        .into_iter()
        .filter_map(|(m, w)| m.then_some(w))
        .collect();
        if missing.is_empty() {
            continue;
        }
        if !diags.keeps_warnings() {
            diags.count_dropped(1);
            continue;
        }
        let res_r: &Resource = &bb.resources[r];
        let mut d = Diagnostic::warning(
            Code::NoToolData,
            format!(
                "resource `{}`: its steps move, but the blackboard gives {} for them: the program uses what the controller has in effect",
                res_r.name.text,
                join_and(&missing.iter().map(|m| format!("no {m}")).collect::<Vec<_>>())
            ),
        )
        .at(res_r.name.span.clone())
        .element(res_r.element.clone());
        for (what, ks) in &res.several {
            let names: Vec<String> = ks
                .iter()
                .map(|k| format!("`{}`", bb.resources[*k].name.text))
                .collect();
            d = d.note(format!(
                "several devices on its controller have a {what} ({}): give the robot its own to say which one its steps use",
                names.join(", ")
            ));
        }
        diags.push(d);
    }
}

fn join_and(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [a] => a.clone(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

/// Calls `f` with every step of `blocks`, in the order the program runs them.
fn each_step(blocks: &[Block], f: &mut dyn FnMut(usize)) {
    for b in blocks {
        match b {
            Block::Step(i) => f(*i),
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    each_step(br, f);
                }
            }
            Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
                for br in branches {
                    each_step(&br.body, f);
                }
            }
            Block::Loop { body, .. } => each_step(body, f),
            Block::Machine(states) => {
                for s in states {
                    each_step(&s.body, f);
                }
            }
            Block::Wait(_) | Block::Tell(_) | Block::Hear(_) | Block::Goto { .. } => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motion_statements_are_recognised_per_language() {
        assert!(moves(Language::Krl, "BAS(#VEL_PTP, 20)\nPTP {A1 0}"));
        assert!(moves(Language::Krl, "  lin_rel {X 10}"));
        assert!(!moves(Language::Krl, "$OUT[1] = TRUE\nLINE = 3"));
        assert!(moves(Language::Rapid, "MoveL p, v200, fine, tool0;"));
        assert!(moves(Language::Rapid, "MoveAbsJ j, v500, fine, tool0;"));
        assert!(!moves(Language::Rapid, "SetDO do1, 1;"));
        assert!(moves(
            Language::UrScript,
            "movel(p[0, 0, 0, 0, 0, 0], a=1.2)"
        ));
        assert!(!moves(Language::UrScript, "movel_done = True"));
    }

    #[test]
    fn frames_are_written_in_each_languages_terms() {
        let f = Frame {
            xyz: [10.0, 0.0, 120.0],
            abc: [90.0, 0.0, 180.0],
        };
        assert_eq!(
            krl_frame_or_number("TOOL", ToolSel::Frame(f)),
            "$TOOL = {X 10, Y 0, Z 120, A 90, B 0, C 180}"
        );
        assert_eq!(
            krl_frame_or_number("BASE", ToolSel::Number(3)),
            "BAS(#BASE, 3)"
        );
        assert_eq!(rapid_pose(f), "[[10, 0, 120], [0, 0.707107, 0.707107, 0]]");
        assert_eq!(ur_pose(f), "p[0.01, 0, 0.12, 2.221441, 2.221441, 0]");
    }
}

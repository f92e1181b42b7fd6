//! Generates large projects in the original tool's format (like
//! `reference/original-sample/`): one resource `KUKA KR15-2` with the skills `Move PTP` (mapped
//! to `SetToolPathVelocity` + `PTP`) and `Move LIN` (mapped to `LIN`), and an SFC of alternating
//! `P2P`/`LIN` steps with `Frame`, `Velocity` and `JointConfig` as direct `<Variable>` children.
//! Optionally every `branch_every` main-line steps a `branch_width`-way simultaneous branch, whose
//! first branch holds a nested branch (one level). Optionally every `select_every` main-line
//! steps a two-way selection (`Part_OK` / `TRUE`, one step each), and with `looped` the whole
//! line is a loop: a step `Loop` after `Start`, and at the end a selection that jumps back to it
//! while `NOT Magazine_Empty` and goes to `End` otherwise (the resource has the two signals).
//!
//! Shared by `examples/generate.rs`, `benches/compile.rs` and any test:
//! `#[path = "../benches/common/generator.rs"] mod generator;`. Output is deterministic: the same
//! [`Spec`] gives the same bytes (a fixed pseudo-random sequence, no `rand`).
//!
//! Size: about 690 bytes per flat step (step + transition), so 100 000 steps give about 69 MB,
//! the size of the original tool's 100k-step project (68 MB).
#![allow(dead_code)]

use std::fmt::Write as _;
use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Spec {
    /// Skill steps (the `Start` and `End` steps not counted).
    pub steps: usize,
    /// Every this many main-line steps a simultaneous branch; 0 = none.
    pub branch_every: usize,
    /// Branches per simultaneous divergence (at least 2 when branching).
    pub branch_width: usize,
    /// Every this many main-line steps a two-way selection; 0 = none.
    pub select_every: usize,
    /// The main line is a loop closed by a jump back.
    pub looped: bool,
}

impl Spec {
    pub fn flat(steps: usize) -> Self {
        Spec {
            steps,
            branch_every: 0,
            branch_width: 0,
            select_every: 0,
            looped: false,
        }
    }

    pub fn branched(steps: usize, every: usize, width: usize) -> Self {
        Spec {
            steps,
            branch_every: every,
            branch_width: width,
            select_every: 0,
            looped: false,
        }
    }
}

/// A generated project on disk.
#[derive(Debug, Clone)]
pub struct Project {
    pub dir: PathBuf,
    pub blackboard: PathBuf,
    pub sfc: PathBuf,
    pub irl: PathBuf,
    pub stats: Stats,
}

/// What the SFC holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Bytes of the SFC file.
    pub sfc_bytes: u64,
    /// Skill steps written (equals [`Spec::steps`]).
    pub skill_steps: usize,
    /// SFC elements (steps, transitions, divergences, convergences).
    pub elements: usize,
    /// Simultaneous divergences.
    pub branches: usize,
}

pub const BLACKBOARD_FILE: &str = "Blackboard.aml";
pub const SFC_FILE: &str = "sfc.xml";
pub const IRL_FILE: &str = "kr15-2.irl";

/// Writes `Blackboard.aml`, `sfc.xml` and `kr15-2.irl` into `dir` (created if needed).
pub fn write_project(dir: &Path, spec: &Spec) -> io::Result<Project> {
    fs::create_dir_all(dir)?;
    let blackboard = dir.join(BLACKBOARD_FILE);
    let sfc = dir.join(SFC_FILE);
    let irl = dir.join(IRL_FILE);
    fs::write(&blackboard, blackboard_text(SFC_FILE, IRL_FILE))?;
    fs::write(&irl, IRL)?;
    let mut w = BufWriter::with_capacity(1 << 20, fs::File::create(&sfc)?);
    let stats = write_sfc(&mut w, spec)?;
    w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    Ok(Project {
        dir: dir.to_owned(),
        blackboard,
        sfc,
        irl,
        stats,
    })
}

/// The SFC as a string.
pub fn sfc_text(spec: &Spec) -> String {
    let mut v = Vec::new();
    write_sfc(&mut v, spec).expect("writing to a Vec does not fail");
    String::from_utf8(v).expect("the generator writes ASCII")
}

/// Writes the SFC.
pub fn write_sfc(w: &mut impl Write, spec: &Spec) -> io::Result<Stats> {
    let mut g = Gen::new(w);
    g.raw(SFC_HEAD);
    write_body(&mut g, spec);
    g.raw(SFC_TAIL);
    g.finish()
}

impl<'w, W: Write> Gen<'w, W> {
    fn new(w: &'w mut W) -> Self {
        Gen {
            w,
            buf: String::with_capacity(4096),
            next_id: 1,
            row: 0,
            rng: Rng(0x5EED_0F1B_2015),
            stats: Stats::default(),
            bytes: 0,
            err: None,
            name: None,
            skills: 0,
            extra: String::new(),
            max_depth: MAX_DEPTH,
        }
    }

    fn finish(mut self) -> io::Result<Stats> {
        self.flush();
        if let Some(e) = self.err {
            return Err(e);
        }
        self.stats.sfc_bytes = self.bytes;
        Ok(self.stats)
    }
}

/// The steps of [`Spec`] between the SFC's head and tail.
fn write_body<W: Write>(g: &mut Gen<'_, W>, spec: &Spec) {
    let start = g.special_step("Start", None);
    let mut last = start;
    if spec.looped {
        let t = g.transition(last);
        last = g.loop_head(t);
    }
    let mut since_branch = 0usize;
    let mut since_select = 0usize;
    let mut last_is_step = true;
    let block = if spec.branch_every > 0 && spec.branch_width >= 2 {
        block_size(spec.branch_width, 0)
    } else {
        usize::MAX
    };
    while g.stats.skill_steps < spec.steps {
        let left = spec.steps - g.stats.skill_steps;
        if spec.select_every > 0 && since_select >= spec.select_every && left >= 3 && last_is_step {
            // A selection after a step; a step after its convergence.
            let conv = g.selection(last);
            last = g.skill_step(Pred::Plain(conv), 0);
            since_select = 0;
            continue;
        }
        let t = g.transition(last);
        if since_branch == spec.branch_every && block <= left {
            last = g.branch(t, spec.branch_width, 0);
            since_branch = 0;
            last_is_step = false;
        } else {
            last = g.skill_step(Pred::Plain(t), 0);
            since_branch += 1;
            last_is_step = true;
        }
        since_select += 1;
    }
    if spec.looped && last_is_step {
        let end = g.loop_end(last);
        g.special_step("End", Some(end));
    } else {
        let t = g.transition(last);
        g.special_step("End", Some(t));
    }
}

/// Nested branches go this deep (0 = the main line's branch).
const MAX_DEPTH: usize = 1;

/// Steps of branch `j` (before any nested branch): 1 or 2.
fn branch_len(j: usize) -> usize {
    1 + j % 2
}

/// Skill steps in one branch block at `depth`.
fn block_size(width: usize, depth: usize) -> usize {
    (0..width)
        .map(|j| {
            branch_len(j)
                + if j == 0 && depth < MAX_DEPTH {
                    // A nested block sits between the first branch's steps, which get one more.
                    1 + block_size(width, depth + 1)
                } else {
                    0
                }
        })
        .sum()
}

/// A connection into an element.
#[derive(Clone, Copy)]
enum Pred {
    Plain(u64),
    /// From a simultaneous divergence's output `branch{n}`.
    Branch(u64, usize),
}

struct Gen<'w, W: Write> {
    w: &'w mut W,
    buf: String,
    next_id: u64,
    row: u64,
    rng: Rng,
    stats: Stats,
    bytes: u64,
    /// The first write error; later writes are skipped.
    err: Option<io::Error>,
    /// The next skill step's name instead of its step type.
    name: Option<String>,
    /// Skill steps name skill `Skill {k % skills}` instead of `Move PTP`/`Move LIN` (0: off).
    skills: usize,
    /// Written into the next skill step after its variables (then cleared).
    extra: String,
    /// Nested simultaneous branches go this deep (0 = the main line's branch).
    max_depth: usize,
}

impl<W: Write> Gen<'_, W> {
    fn id(&mut self) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        self.stats.elements += 1;
        id
    }

    fn y(&mut self) -> u64 {
        self.row += 1;
        self.row * 40
    }

    fn raw(&mut self, s: &str) {
        self.buf.push_str(s);
    }

    fn flush(&mut self) {
        if self.err.is_none() {
            self.bytes += self.buf.len() as u64;
            if let Err(e) = self.w.write_all(self.buf.as_bytes()) {
                self.err = Some(e);
            }
        }
        self.buf.clear();
    }

    fn maybe_flush(&mut self) {
        if self.buf.len() > 3000 {
            self.flush();
        }
    }

    fn conn_in(&mut self, p: Pred) {
        let b = &mut self.buf;
        match p {
            Pred::Plain(id) => {
                let _ = write!(
                    b,
                    "<connectionPointIn><connection refLocalId=\"{id}\"/></connectionPointIn>"
                );
            }
            Pred::Branch(id, n) => {
                let _ = write!(
                    b,
                    "<connectionPointIn><connection refLocalId=\"{id}\" formalParameter=\"branch{n}\"/></connectionPointIn>"
                );
            }
        }
    }

    fn special_step(&mut self, name: &str, pred: Option<u64>) -> u64 {
        let id = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<step localId=\"{id}\" name=\"{name}\" initialStep=\"true\">\n <position x=\"0\" y=\"{y}\"/>\n "
        );
        match pred {
            Some(p) => self.conn_in(Pred::Plain(p)),
            None => self.raw("<connectionPointOut formalParameter=\"\"/>"),
        }
        self.raw("\n</step>\n");
        self.maybe_flush();
        id
    }

    fn skill_step(&mut self, pred: Pred, column: usize) -> u64 {
        let id = self.id();
        let y = self.y();
        let lin = self.stats.skill_steps % 2 == 1;
        self.stats.skill_steps += 1;
        let (kind, skill) = if lin {
            ("LIN", "Move LIN")
        } else {
            ("P2P", "Move PTP")
        };
        let name = self.name.clone();
        let kind = name.as_deref().unwrap_or(kind);
        let own_skill;
        let skill = if self.skills > 0 {
            own_skill = format!("Skill {}", (self.stats.skill_steps - 1) % self.skills);
            own_skill.as_str()
        } else {
            skill
        };
        let x = column * 200;
        let r = &mut self.rng;
        // Millimetres with one decimal, whole degrees: a reachable-looking KR15 workspace.
        let fx = r.range(-12000, 12000) as f64 / 10.0;
        let fy = r.range(-12000, 12000) as f64 / 10.0;
        let fz = r.range(0, 15000) as f64 / 10.0;
        let (a, b, c) = (r.range(-180, 180), r.range(-90, 90), r.range(-180, 180));
        let vel = r.range(5, 100) as f64 / 100.0;
        let dur = r.range(2, 16) as f64 / 4.0;
        let (j1, j2) = (r.range(0, 7), r.range(0, 63));
        let _ = write!(
            self.buf,
            "<step localId=\"{id}\" name=\"{kind}\">\n <position x=\"{x}\" y=\"{y}\"/>\n "
        );
        self.conn_in(pred);
        let _ = write!(
            self.buf,
            "\n <connectionPointOut formalParameter=\"\"/>\n \
             <addData><data name=\"iwb\" handleUnknown=\"preserve\"><iwb>\
             <time duration=\"{dur}\"/><ressources><ressource name=\"KUKA KR15-2\"/></ressources>\
             <skill name=\"{skill}\"/></iwb></data></addData>\n \
             <Variable name=\"Frame\" Value=\"({fx}, {fy}, {fz}, {a}, {b}, {c})\"/>\n \
             <Variable name=\"Velocity\" Value=\"{vel}\"/>\n \
             <Variable name=\"JointConfig\" Value=\"({j1}, {j2})\"/>\n"
        );
        if !self.extra.is_empty() {
            let extra = std::mem::take(&mut self.extra);
            self.raw(&extra);
        }
        self.raw("</step>\n");
        self.maybe_flush();
        id
    }

    fn transition(&mut self, pred: u64) -> u64 {
        let id = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<transition localId=\"{id}\">\n <position x=\"0\" y=\"{y}\"/>\n "
        );
        self.conn_in(Pred::Plain(pred));
        self.raw(
            "<connectionPointOut/>\n \
             <condition><inline name=\"\"><ST><xhtml:p>TRUE</xhtml:p></ST></inline></condition>\n\
             </transition>\n",
        );
        self.maybe_flush();
        id
    }

    /// A transition with a condition (inline ST, escaped by the caller).
    fn guarded(&mut self, pred: Pred, cond: &str) -> u64 {
        let id = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<transition localId=\"{id}\">\n <position x=\"0\" y=\"{y}\"/>\n "
        );
        self.conn_in(pred);
        let _ = write!(
            self.buf,
            "<connectionPointOut/>\n \
             <condition><inline name=\"\"><ST><xhtml:p>{cond}</xhtml:p></ST></inline></condition>\n\
             </transition>\n"
        );
        self.maybe_flush();
        id
    }

    /// A selection divergence after step `pred` with `n` outputs.
    fn selection_divergence(&mut self, pred: u64, n: usize) -> u64 {
        let div = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<selectionDivergence localId=\"{div}\">\n <position x=\"0\" y=\"{y}\"/>\n "
        );
        self.conn_in(Pred::Plain(pred));
        for k in 0..n {
            let _ = write!(
                self.buf,
                "\n <connectionPointOut formalParameter=\"branch{k}\"/>"
            );
        }
        self.raw("\n</selectionDivergence>\n");
        div
    }

    /// A two-way selection after step `pred` (`Part_OK`, then `TRUE`), one step per branch;
    /// returns the convergence.
    fn selection(&mut self, pred: u64) -> u64 {
        let div = self.selection_divergence(pred, 2);
        let mut lasts = Vec::with_capacity(2);
        for (k, cond) in ["Part_OK", "TRUE"].into_iter().enumerate() {
            let t = self.guarded(Pred::Branch(div, k), cond);
            let s = self.skill_step(Pred::Plain(t), k);
            lasts.push(self.transition(s));
        }
        let conv = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<selectionConvergence localId=\"{conv}\">\n <position x=\"0\" y=\"{y}\"/>"
        );
        for l in lasts {
            self.raw("\n ");
            self.conn_in(Pred::Plain(l));
        }
        self.raw("\n <connectionPointOut/>\n</selectionConvergence>\n");
        self.maybe_flush();
        conv
    }

    /// The loop's head: a skill step named `Loop` after transition `pred`.
    fn loop_head(&mut self, pred: u64) -> u64 {
        self.loop_head_named(pred, "Loop")
    }

    fn loop_head_named(&mut self, pred: u64, name: &str) -> u64 {
        self.name = Some(name.to_owned());
        let id = self.skill_step(Pred::Plain(pred), 0);
        self.name = None;
        id
    }

    /// The loop's end after step `pred`: a selection that jumps back to `Loop` while
    /// `NOT Magazine_Empty`; returns the transition to the end step.
    fn loop_end(&mut self, pred: u64) -> u64 {
        self.loop_end_named(pred, "Loop")
    }

    fn loop_end_named(&mut self, pred: u64, target: &str) -> u64 {
        let div = self.selection_divergence(pred, 2);
        let back = self.guarded(Pred::Branch(div, 0), "NOT Magazine_Empty");
        let id = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<jumpStep localId=\"{id}\" targetName=\"{target}\">\n <position x=\"0\" y=\"{y}\"/>\n "
        );
        self.conn_in(Pred::Plain(back));
        self.raw("\n</jumpStep>\n");
        self.guarded(Pred::Branch(div, 1), "Magazine_Empty")
    }

    /// A `width`-way simultaneous branch after transition `pred`; returns the convergence.
    fn branch(&mut self, pred: u64, width: usize, depth: usize) -> u64 {
        self.stats.branches += 1;
        let div = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<simultaneousDivergence localId=\"{div}\">\n <position x=\"0\" y=\"{y}\"/>\n "
        );
        self.conn_in(Pred::Plain(pred));
        for n in 0..width {
            let _ = write!(
                self.buf,
                "\n <connectionPointOut formalParameter=\"branch{n}\"/>"
            );
        }
        self.raw("\n</simultaneousDivergence>\n");
        let mut lasts = Vec::with_capacity(width);
        for j in 0..width {
            let column = depth * width + j;
            let mut last = self.skill_step(Pred::Branch(div, j), column);
            if j == 0 && depth < self.max_depth {
                let t = self.transition(last);
                let conv = self.branch(t, width, depth + 1);
                let t = self.transition(conv);
                last = self.skill_step(Pred::Plain(t), column);
            }
            for _ in 1..branch_len(j) {
                let t = self.transition(last);
                last = self.skill_step(Pred::Plain(t), column);
            }
            lasts.push(last);
        }
        let conv = self.id();
        let y = self.y();
        let _ = write!(
            self.buf,
            "<simultaneousConvergence localId=\"{conv}\">\n <position x=\"0\" y=\"{y}\"/>"
        );
        for l in lasts {
            self.raw("\n ");
            self.conn_in(Pred::Plain(l));
        }
        self.raw("\n <connectionPointOut/>\n</simultaneousConvergence>\n");
        self.maybe_flush();
        conv
    }
}

/// SplitMix64: a fixed, portable pseudo-random sequence.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform-ish in `lo..=hi`.
    fn range(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next() % (hi - lo + 1) as u64) as i64
    }
}

const SFC_HEAD: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<!-- GENERATED by examples/generate.rs (benches/common/generator.rs) in the original tool's format;
     see reference/original-sample/sfc.xml. -->
<project xmlns="http://www.plcopen.org/xml/tc6_0201" xmlns:xhtml="http://www.w3.org/1999/xhtml">
  <fileHeader companyName="iwb" productName="Generated" productVersion="1" creationDateTime="2015-05-26T12:00:00"/>
  <contentHeader name="Generated">
    <coordinateInfo>
      <fbd><scaling x="1" y="1"/></fbd>
      <ld><scaling x="1" y="1"/></ld>
      <sfc><scaling x="1" y="1"/></sfc>
    </coordinateInfo>
  </contentHeader>
  <types>
    <dataTypes/>
    <pous>
      <pou name="Generated" pouType="program">
        <body>
          <SFC>
"#;

const SFC_TAIL: &str = r#"          </SFC>
        </body>
      </pou>
    </pous>
  </types>
  <instances><configurations/></instances>
</project>
"#;

/// The IRL file (the sample's `kr15-2.irl`).
pub const IRL: &str = "<irl>
\t<info name=\"KUKA KR15-2\"/>
\t<def>
\t\t<definition name=\"SetVelCP\">
\t\t\t<parameter name=\"VALUE\"/>
\t\t\tDEF SetVelCP(VALUE:IN)
\t\t\t\tDECL REAL VALUE
\t\t\t\t$VEL.CP = VALUE
\t\t\t\tRETURN
\t\t\tEND
\t\t</definition>
\t</def>
\t<src>
\t\t<function-call name=\"SetVelCP\">
\t\t\t<parameter name=\"VALUE\"/>
\t\t\tSetVelCP (VALUE)
\t\t</function-call>
\t\t<function-call name=\"PTP\">
\t\t\t<parameter name=\"X\"/>
\t\t\t<parameter name=\"Y\"/>
\t\t\t<parameter name=\"Z\"/>
\t\t\t<parameter name=\"A\"/>
\t\t\t<parameter name=\"B\"/>
\t\t\t<parameter name=\"C\"/>
\t\t\tPTP {X, Y, Z, A, B, C}
\t\t</function-call>
\t\t<function-call name=\"LIN\">
\t\t\t<parameter name=\"X\"/>
\t\t\t<parameter name=\"Y\"/>
\t\t\t<parameter name=\"Z\"/>
\t\t\t<parameter name=\"A\"/>
\t\t\t<parameter name=\"B\"/>
\t\t\t<parameter name=\"C\"/>
\t\t\tLIN {X, Y, Z, A, B, C}
\t\t</function-call>
\t</src>
</irl>
";

/// The blackboard (the sample's `Blackboard.aml`), naming the SFC and the IRL file by these
/// `refURI`s (relative to the blackboard's folder, e.g. `../sfc.xml`).
pub fn blackboard_text(sfc_ref: &str, irl_ref: &str) -> String {
    BLACKBOARD
        .replace("{{SFC}}", sfc_ref)
        .replace("{{IRL}}", irl_ref)
}

const BLACKBOARD: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<CAEXFile FileName="Blackboard.aml" SchemaVersion="2.15" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="CAEX_ClassModel_V2.15.xsd">
  <!-- GENERATED by examples/generate.rs: reference/original-sample/Blackboard.aml -->
  <InstanceHierarchy Name="Blackboard">
    <InternalElement Name="Ressourcen" ID="{00000000-0000-0000-0000-000000000001}">
      <InternalElement Name="KUKA KR15-2" ID="{00000000-0000-0000-0000-000000000002}">
        <ExternalInterface Name="Part_OK" ID="{00000000-0000-0000-0000-000000000101}" RefBaseClassPath="AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface">
          <Attribute Name="Number" AttributeDataType="xs:integer"><Value>1</Value></Attribute>
        </ExternalInterface>
        <ExternalInterface Name="Magazine_Empty" ID="{00000000-0000-0000-0000-000000000102}" RefBaseClassPath="AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface">
          <Attribute Name="Number" AttributeDataType="xs:integer"><Value>2</Value></Attribute>
        </ExternalInterface>
        <InternalElement Name="Skills" ID="{00000000-0000-0000-0000-000000000003}">
          <InternalElement Name="Move PTP" ID="{00000000-0000-0000-0000-000000000004}">
            <Attribute Name="Velocity" AttributeDataType="xs:double" Unit="m/s">
              <Description>TCP movement speed</Description>
              <Value>Velocity</Value>
            </Attribute>
            <Attribute Name="End Position" AttributeDataType="xs:string">
              <Description>Frame Object</Description>
              <Value>Frame</Value>
              <Attribute Name="x" AttributeDataType="xs:double"><Description>x coordinate of destination</Description><Value>0</Value></Attribute>
              <Attribute Name="y" AttributeDataType="xs:double"><Value>1</Value></Attribute>
              <Attribute Name="z" AttributeDataType="xs:double"><Value>2</Value></Attribute>
              <Attribute Name="a" AttributeDataType="xs:double"><Value>3</Value></Attribute>
              <Attribute Name="b" AttributeDataType="xs:double"><Value>4</Value></Attribute>
              <Attribute Name="c" AttributeDataType="xs:double"><Value>5</Value></Attribute>
            </Attribute>
            <ExternalInterface Name="FunctionMapping" ID="{00000000-0000-0000-0000-000000000005}" RefBaseClassPath="IWB StateModelInterfaceLib/SkillMapping">
              <Attribute Name="Name" AttributeDataType="xs:string"><Description>Name of the mapped Function</Description><Value>SetToolPathVelocity</Value></Attribute>
              <Attribute Name="Order"><Description>Execution order of function</Description><Value>0</Value></Attribute>
              <Attribute Name="Mapping"><Description>Attribute name mapping</Description>
                <Attribute Name="Velocity" AttributeDataType="xs:string"><Value>value</Value></Attribute>
              </Attribute>
            </ExternalInterface>
            <ExternalInterface Name="FunctionMapping" ID="{00000000-0000-0000-0000-000000000006}" RefBaseClassPath="IWB StateModelInterfaceLib/SkillMapping">
              <Attribute Name="Name" AttributeDataType="xs:string"><Value>PTP</Value></Attribute>
              <Attribute Name="Order"><Value>1</Value></Attribute>
              <Attribute Name="Mapping">
                <Attribute Name="End Position">
                  <Attribute Name="x"><Value>X</Value></Attribute>
                  <Attribute Name="y"><Value>Y</Value></Attribute>
                  <Attribute Name="z"><Value>Z</Value></Attribute>
                  <Attribute Name="a"><Value>A</Value></Attribute>
                  <Attribute Name="b"><Value>B</Value></Attribute>
                  <Attribute Name="c"><Value>C</Value></Attribute>
                </Attribute>
              </Attribute>
            </ExternalInterface>
          </InternalElement>
          <InternalElement Name="Move LIN" ID="{00000000-0000-0000-0000-000000000007}">
            <Attribute Name="End Position" AttributeDataType="xs:string">
              <Value>Frame</Value>
              <Attribute Name="x" AttributeDataType="xs:double"><Value>0</Value></Attribute>
              <Attribute Name="y" AttributeDataType="xs:double"><Value>1</Value></Attribute>
              <Attribute Name="z" AttributeDataType="xs:double"><Value>2</Value></Attribute>
              <Attribute Name="a" AttributeDataType="xs:double"><Value>3</Value></Attribute>
              <Attribute Name="b" AttributeDataType="xs:double"><Value>4</Value></Attribute>
              <Attribute Name="c" AttributeDataType="xs:double"><Value>5</Value></Attribute>
            </Attribute>
            <ExternalInterface Name="FunctionMapping" ID="{00000000-0000-0000-0000-000000000008}" RefBaseClassPath="IWB StateModelInterfaceLib/SkillMapping">
              <Attribute Name="Name"><Value>LIN</Value></Attribute>
              <Attribute Name="Order"><Value>0</Value></Attribute>
              <Attribute Name="Mapping">
                <Attribute Name="End Position">
                  <Attribute Name="x"><Value>X</Value></Attribute>
                  <Attribute Name="y"><Value>Y</Value></Attribute>
                  <Attribute Name="z"><Value>Z</Value></Attribute>
                  <Attribute Name="a"><Value>A</Value></Attribute>
                  <Attribute Name="b"><Value>B</Value></Attribute>
                  <Attribute Name="c"><Value>C</Value></Attribute>
                </Attribute>
              </Attribute>
            </ExternalInterface>
          </InternalElement>
        </InternalElement>
        <InternalElement Name="FunctionDescription" ID="{00000000-0000-0000-0000-000000000009}">
          <InternalElement Name="PTP" ID="{00000000-0000-0000-0000-000000000010}">
            <Attribute Name="x" AttributeDataType="xs:double"><Description>x coordinate destination</Description><Value>0.0</Value></Attribute>
            <Attribute Name="Description" AttributeDataType="xs:string"><Value>Execute motion to destination</Value></Attribute>
            <ExternalInterface Name="FunctionDataInterface" ID="{00000000-0000-0000-0000-000000000011}" RefBaseClassPath="IWB StateModelInterfaceLib/FunctionLogic">
              <Attribute Name="Name" AttributeDataType="xs:string"><Description>Name of the function to call</Description><Value>PTP</Value></Attribute>
              <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Description>Path to IRL File</Description><Value>{{IRL}}</Value></Attribute>
            </ExternalInterface>
          </InternalElement>
          <InternalElement Name="LIN" ID="{00000000-0000-0000-0000-000000000012}">
            <ExternalInterface Name="FunctionDataInterface" ID="{00000000-0000-0000-0000-000000000013}" RefBaseClassPath="IWB StateModelInterfaceLib/FunctionLogic">
              <Attribute Name="Name" AttributeDataType="xs:string"><Value>LIN</Value></Attribute>
              <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>{{IRL}}</Value></Attribute>
            </ExternalInterface>
          </InternalElement>
          <InternalElement Name="SetToolPathVelocity" ID="{00000000-0000-0000-0000-000000000014}">
            <ExternalInterface Name="FunctionDataInterface" ID="{00000000-0000-0000-0000-000000000015}" RefBaseClassPath="IWB StateModelInterfaceLib/FunctionLogic">
              <Attribute Name="Name" AttributeDataType="xs:string"><Value>SetVelCP</Value></Attribute>
              <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>{{IRL}}</Value></Attribute>
            </ExternalInterface>
          </InternalElement>
        </InternalElement>
      </InternalElement>
    </InternalElement>
    <InternalElement Name="Process Sequenz" ID="{00000000-0000-0000-0000-000000000016}">
      <ExternalInterface Name="SFC Benutzereingabe" ID="{00000000-0000-0000-0000-000000000017}" RefBaseClassPath="AutomationMLInterfaceClassLib/AutomationMLBaseInterface/ExternalDataConnector">
        <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>{{SFC}}</Value></Attribute>
      </ExternalInterface>
    </InternalElement>
    <InternalElement Name="Code" ID="{00000000-0000-0000-0000-000000000018}">
      <ExternalInterface Name="KRL code" ID="{00000000-0000-0000-0000-000000000019}" RefBaseClassPath="AutomationMLInterfaceClassLib/AutomationMLBaseInterface/ExternalDataConnector">
        <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>none</Value></Attribute>
      </ExternalInterface>
    </InternalElement>
  </InstanceHierarchy>
</CAEXFile>
"#;

/// The input dimensions a shape can grow in (issue 13), each with what `n` counts.
pub const DIMENSIONS: &[(&str, &str)] = &[
    ("steps", "skill steps in a flat line"),
    ("vars", "extra <Variable>s in one step (16 steps)"),
    (
        "skills",
        "skills of the resource, step k using skill k (n steps)",
    ),
    ("resources", "resources before the one the 16 steps use"),
    (
        "functions",
        "functions (mappings) of one skill, all calling SetVelCP (16 steps)",
    ),
    (
        "irl",
        "IRL function-calls and definitions, each called by its own function of one skill (16 steps)",
    ),
    (
        "files",
        "IRL files, each read by its own function of one skill (16 steps)",
    ),
    (
        "chain",
        "IRL definitions each called by the one before, the first by `SetVelCP` (16 steps)",
    ),
    ("unused", "IRL definitions no program calls (16 steps)"),
    (
        "signals",
        "signals of the resource; the first condition reads up to 300, the others the last ones (16 steps)",
    ),
    (
        "cond",
        "terms of one transition condition (16 steps; a condition has at most 1024 tokens: n <= 370)",
    ),
    ("width", "branches of one simultaneous divergence"),
    (
        "depth",
        "nesting depth of 2-way simultaneous branches (at most 127)",
    ),
    ("loops", "loops one after another, each closed by a jump"),
    (
        "nest",
        "elements unknown to the reader nested n deep inside one step (16 steps)",
    ),
    (
        "markup",
        "references, comments and CDATA sections (what the SFC's producer leaves to quick-xml, one event at a time) in one element of one step, n of each (16 steps)",
    ),
];

/// Writes a project that grows in one dimension of [`DIMENSIONS`] with `n`; the rest stays
/// small. `None` for an unknown dimension.
pub fn write_shape(dir: &Path, dim: &str, n: usize) -> Option<io::Result<Project>> {
    let mut bb = blackboard_text(SFC_FILE, IRL_FILE);
    let mut irl = IRL.to_owned();
    let mut spec = Spec::flat(16);
    let mut cond = None::<String>;
    // Conditions of the transitions after the first (each names one signal).
    let mut later = None::<usize>;
    let mut skills = 0;
    let mut extra = String::new();
    // The IRL files of the "files" dimension, one per function (copies of the one IRL file).
    let mut irl_files: Vec<String> = Vec::new();
    let anchor_skills =
        "        </InternalElement>\n        <InternalElement Name=\"FunctionDescription\"";
    let anchor_functions = "{00000000-0000-0000-0000-000000000009}\">\n";
    let anchor_signals = "        <InternalElement Name=\"Skills\"";
    let anchor_resources = "      <InternalElement Name=\"KUKA KR15-2\"";
    let id = |kind: u32, i: usize| format!("{{{kind:08X}-0000-0000-0000-{i:012X}}}");
    let insert = |bb: &mut String, anchor: &str, before: bool, text: &str| {
        let at = bb.find(anchor).expect("anchor in the blackboard");
        let at = if before { at } else { at + anchor.len() };
        bb.insert_str(at, text);
    };
    // A skill calling each of `functions` with its velocity.
    let many = |functions: &[String]| {
        let mut t = format!(
            "          <InternalElement Name=\"Skill 0\" ID=\"{}\">\n            <Attribute Name=\"Velocity\" AttributeDataType=\"xs:double\"><Value>Velocity</Value></Attribute>\n",
            id(0x5C, 0)
        );
        for (k, f) in functions.iter().enumerate() {
            let _ = writeln!(
                t,
                "            <ExternalInterface Name=\"FunctionMapping\" ID=\"{}\" RefBaseClassPath=\"IWB StateModelInterfaceLib/SkillMapping\"><Attribute Name=\"Name\"><Value>{f}</Value></Attribute><Attribute Name=\"Order\"><Value>{k}</Value></Attribute><Attribute Name=\"Mapping\"><Attribute Name=\"Velocity\"><Value>value</Value></Attribute></Attribute></ExternalInterface>",
                id(0x3A, k)
            );
        }
        t.push_str("          </InternalElement>\n");
        t
    };
    let function = |name: &str, command: &str, k: usize, file: &str| {
        format!(
            "          <InternalElement Name=\"{name}\" ID=\"{}\"><ExternalInterface Name=\"FunctionDataInterface\" ID=\"{}\" RefBaseClassPath=\"IWB StateModelInterfaceLib/FunctionLogic\"><Attribute Name=\"Name\"><Value>{command}</Value></Attribute><Attribute Name=\"refURI\"><Value>{file}</Value></Attribute></ExternalInterface></InternalElement>\n",
            id(0xF0, k),
            id(0xF1, k)
        )
    };
    match dim {
        "steps" => spec = Spec::flat(n),
        "vars" => {
            for i in 0..n {
                let _ = writeln!(extra, " <Variable name=\"Extra{i}\" Value=\"{i}\"/>");
            }
        }
        "nest" => {
            extra = format!(" {}{}\n", "<x>".repeat(n), "</x>".repeat(n));
        }
        "markup" => {
            extra = format!(
                " <x>{}</x>\n",
                "a &amp; b &#x41;<!-- c --><![CDATA[d]]> ".repeat(n)
            );
        }
        "skills" => {
            let mut t = String::new();
            for k in 0..n {
                let _ = writeln!(
                    t,
                    "          <InternalElement Name=\"Skill {k}\" ID=\"{}\"><Attribute Name=\"End Position\" AttributeDataType=\"xs:string\"><Value>Frame</Value><Attribute Name=\"x\" AttributeDataType=\"xs:double\"><Value>0</Value></Attribute><Attribute Name=\"y\" AttributeDataType=\"xs:double\"><Value>1</Value></Attribute><Attribute Name=\"z\" AttributeDataType=\"xs:double\"><Value>2</Value></Attribute><Attribute Name=\"a\" AttributeDataType=\"xs:double\"><Value>3</Value></Attribute><Attribute Name=\"b\" AttributeDataType=\"xs:double\"><Value>4</Value></Attribute><Attribute Name=\"c\" AttributeDataType=\"xs:double\"><Value>5</Value></Attribute></Attribute><ExternalInterface Name=\"FunctionMapping\" ID=\"{}\" RefBaseClassPath=\"IWB StateModelInterfaceLib/SkillMapping\"><Attribute Name=\"Name\"><Value>LIN</Value></Attribute><Attribute Name=\"Order\"><Value>0</Value></Attribute><Attribute Name=\"Mapping\"><Attribute Name=\"End Position\"><Attribute Name=\"x\"><Value>X</Value></Attribute><Attribute Name=\"y\"><Value>Y</Value></Attribute><Attribute Name=\"z\"><Value>Z</Value></Attribute><Attribute Name=\"a\"><Value>A</Value></Attribute><Attribute Name=\"b\"><Value>B</Value></Attribute><Attribute Name=\"c\"><Value>C</Value></Attribute></Attribute></Attribute></ExternalInterface></InternalElement>",
                    id(0x5C, k),
                    id(0x3A, k)
                );
            }
            insert(&mut bb, anchor_skills, true, &t);
            spec = Spec::flat(n);
            skills = n;
        }
        "resources" => {
            let mut t = String::new();
            for k in 0..n {
                let _ = writeln!(
                    t,
                    "      <InternalElement Name=\"Robot {k}\" ID=\"{}\"><InternalElement Name=\"Skills\" ID=\"{}\"/></InternalElement>",
                    id(0xAE, k),
                    id(0xAF, k)
                );
            }
            insert(&mut bb, anchor_resources, true, &t);
        }
        "functions" | "irl" | "files" => {
            let names: Vec<String> = (0..n).map(|k| format!("Function {k}")).collect();
            let mut t = String::new();
            let (mut calls, mut defs) = (String::new(), String::new());
            for (k, f) in names.iter().enumerate() {
                let command = if dim == "irl" {
                    let c = format!("Call{k}");
                    let _ = write!(
                        calls,
                        "\t\t<function-call name=\"{c}\">\n\t\t\t<parameter name=\"VALUE\"/>\n\t\t\t{c} (VALUE)\n\t\t</function-call>\n"
                    );
                    let _ = write!(
                        defs,
                        "\t\t<definition name=\"{c}\">\n\t\t\t<parameter name=\"VALUE\"/>\n\t\t\tDEF {c}(VALUE:IN)\n\t\t\t\tDECL REAL VALUE\n\t\t\t\t$VEL.CP = VALUE\n\t\t\tEND\n\t\t</definition>\n"
                    );
                    c
                } else {
                    "SetVelCP".to_owned()
                };
                let file = if dim == "files" {
                    irl_files.push(format!("irl/f{k}.irl"));
                    irl_files.last().unwrap().as_str()
                } else {
                    IRL_FILE
                };
                t.push_str(&function(f, &command, k, file));
            }
            insert(&mut bb, anchor_functions, false, &t);
            insert(&mut bb, anchor_skills, true, &many(&names));
            irl = irl.replace("\t</src>", &format!("{calls}\t</src>"));
            irl = irl.replace("\t</def>", &format!("{defs}\t</def>"));
            skills = 1;
        }
        "chain" => {
            // `SetVelCP` calls `Helper0`, each `HelperK` calls the next; written last first,
            // so that each one is found through the one taken before it.
            let mut defs = String::new();
            for k in (0..n).rev() {
                let next = if k + 1 < n {
                    format!("\t\t\t\tHelper{}()\n", k + 1)
                } else {
                    String::new()
                };
                let _ = write!(
                    defs,
                    "\t\t<definition name=\"Helper{k}\">\n\t\t\tDEF Helper{k}()\n{next}\t\t\t\t$OUT[1] = TRUE\n\t\t\tEND\n\t\t</definition>\n"
                );
            }
            irl = irl.replace(
                "\t\t\t\t$VEL.CP = VALUE\n",
                "\t\t\t\t$VEL.CP = VALUE\n\t\t\t\tHelper0()\n",
            );
            irl = irl.replace("\t</def>", &format!("{defs}\t</def>"));
        }
        "unused" => {
            // A library of helpers the steps do not call: each is looked for in the programs.
            let mut defs = String::new();
            for k in 0..n {
                let _ = write!(
                    defs,
                    "\t\t<definition name=\"Unused{k}\">\n\t\t\tDEF Unused{k}()\n\t\t\t\t$OUT[1] = TRUE\n\t\t\tEND\n\t\t</definition>\n"
                );
            }
            irl = irl.replace("\t</def>", &format!("{defs}\t</def>"));
        }
        "signals" => {
            let mut t = String::new();
            let mut c = String::new();
            for k in 0..n {
                let _ = writeln!(
                    t,
                    "        <ExternalInterface Name=\"S{k}\" ID=\"{}\" RefBaseClassPath=\"AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface\"><Attribute Name=\"Number\" AttributeDataType=\"xs:integer\"><Value>{}</Value></Attribute></ExternalInterface>",
                    id(0x51, k),
                    // I/O indexes go up to 8192 (read::blackboard::MAX_IO); they may repeat.
                    k % 8000 + 3
                );
                if k < 300 {
                    if k > 0 {
                        c.push_str(" OR ");
                    }
                    let _ = write!(c, "S{k}");
                }
            }
            insert(&mut bb, anchor_signals, true, &t);
            cond = Some(c);
            later = Some(n);
        }
        "cond" => {
            let mut c = String::new();
            for k in 0..n {
                if k > 0 {
                    c.push_str(if k % 2 == 1 { " AND " } else { " OR " });
                }
                c.push_str(if k % 3 == 0 {
                    "Part_OK"
                } else {
                    "NOT Magazine_Empty"
                });
            }
            cond = Some(c);
        }
        "width" | "depth" | "loops" | "loopnest" | "jumps" | "overlap" => {}
        _ => return None,
    }
    Some((|| {
        fs::create_dir_all(dir)?;
        let blackboard = dir.join(BLACKBOARD_FILE);
        let sfc = dir.join(SFC_FILE);
        let irl_path = dir.join(IRL_FILE);
        fs::write(&blackboard, bb)?;
        fs::write(&irl_path, &irl)?;
        for f in &irl_files {
            let path = dir.join(f);
            fs::create_dir_all(path.parent().expect("a file in a folder"))?;
            fs::write(path, &irl)?;
        }
        let mut w = BufWriter::with_capacity(1 << 20, fs::File::create(&sfc)?);
        let mut g = Gen::new(&mut w);
        g.skills = skills;
        g.extra = extra;
        g.raw(SFC_HEAD);
        match dim {
            "width" | "depth" => {
                let start = g.special_step("Start", None);
                let t = g.transition(start);
                let conv = if dim == "width" {
                    g.max_depth = 0;
                    g.branch(t, n, 0)
                } else {
                    g.max_depth = n.saturating_sub(1);
                    g.branch(t, 2, 0)
                };
                let t = g.transition(conv);
                g.special_step("End", Some(t));
            }
            "loops" => {
                let start = g.special_step("Start", None);
                let mut t = g.transition(start);
                for k in 0..n {
                    let name = format!("Loop{k}");
                    let head = g.loop_head_named(t, &name);
                    let t2 = g.transition(head);
                    let body = g.skill_step(Pred::Plain(t2), 0);
                    t = g.loop_end_named(body, &name);
                }
                g.special_step("End", Some(t));
            }
            "jumps" | "overlap" => {
                // Flow beyond the structured forms (docs/INPUTS.md): blocks of a head step `Jk`, a
                // body step `Bk` and a selection that jumps away or goes on. `jumps`: forward,
                // over the next block (to `Jk+2`); `overlap`: back into the previous block's
                // body (`Bk-1`), so each loop overlaps the next. Both compile into states.
                let start = g.special_step("Start", None);
                let mut t = g.transition(start);
                for k in 0..n {
                    let head = g.loop_head_named(t, &format!("J{k}"));
                    let t2 = g.transition(head);
                    let body = g.loop_head_named(t2, &format!("B{k}"));
                    let target = match dim {
                        "jumps" if k + 2 < n => format!("J{}", k + 2),
                        "jumps" => format!("J{k}"),
                        _ => format!("B{}", k.saturating_sub(1)),
                    };
                    t = g.loop_end_named(body, &target);
                }
                g.special_step("End", Some(t));
            }
            "loopnest" => {
                // Loop k inside loop k - 1: the heads `Loop0` … in a row, one body step, then
                // the ends from the innermost out, a step between two of them.
                let start = g.special_step("Start", None);
                let mut t = g.transition(start);
                for k in 0..n {
                    let head = g.loop_head_named(t, &format!("Loop{k}"));
                    t = g.transition(head);
                }
                let mut last = g.skill_step(Pred::Plain(t), 0);
                for k in (0..n).rev() {
                    t = g.loop_end_named(last, &format!("Loop{k}"));
                    if k > 0 {
                        last = g.skill_step(Pred::Plain(t), 0);
                    }
                }
                g.special_step("End", Some(t));
            }
            _ => match cond {
                Some(c) => {
                    // The first transition carries the condition.
                    let start = g.special_step("Start", None);
                    let t = g.guarded(Pred::Plain(start), &c);
                    let mut last = g.skill_step(Pred::Plain(t), 0);
                    for k in 1..spec.steps {
                        let t = match later {
                            Some(n) if n > 0 => {
                                let s = format!("S{}", n - 1 - k % n);
                                g.guarded(Pred::Plain(last), &s)
                            }
                            _ => g.transition(last),
                        };
                        last = g.skill_step(Pred::Plain(t), 0);
                    }
                    let t = g.transition(last);
                    g.special_step("End", Some(t));
                }
                None => write_body(&mut g, &spec),
            },
        }
        g.raw(SFC_TAIL);
        let stats = g.finish()?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        Ok(Project {
            dir: dir.to_owned(),
            blackboard,
            sfc,
            irl: irl_path,
            stats,
        })
    })())
}

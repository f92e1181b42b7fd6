//! A resource's tool, base and load from its blackboard attributes (docs/INPUTS.md, "Tool, base
//! and load"): `Tool`/`TCP` and `Base` as AutomationML frames, `ToolNumber` and `BaseNumber`
//! (the controller's own tools and bases), `Load`, `Mass` and `CenterOfMass`. A robot's `Payload`
//! (its rated payload, as catalogues give it) and a robot's `Mass` (its own weight) are no load.
//!
//! A frame is AutomationML's `Frame` attribute type (`AutomationMLBaseAttributeTypeLib/Frame`,
//! IEC 62714-3): sub-attributes `x`, `y`, `z` in metres and `rx`, `ry`, `rz` in degrees, rotated
//! about the fixed axes X, then Y, then Z. That is KUKA's A-B-C turned around: `A = rz`,
//! `B = ry`, `C = rx` (`R = Rz(rz)·Ry(ry)·Rx(rx)`), and the plan's frames are in mm, so the model
//! keeps `x·1000, y·1000, z·1000, rz, ry, rx` ([`crate::model::Frame`]). A sub-attribute's CAEX
//! `Unit` (`m`, `mm`, `cm`; `degree`, `deg`, `°`, `rad`) is honoured.
//!
//! Every value that cannot be used is `E217`, located at it; the resource then has none of it.

use roxmltree::Node;

use super::xml::{attr_span, caex_attr, caex_name, child, children, tag_span};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Span};
use crate::model::{Frame, Tooling};
use crate::names;

/// The attribute names read here (each with its aliases), for the near-name warning `W208`.
pub const NAMES: [&str; 8] = [
    "Tool",
    "TCP",
    "ToolNumber",
    "Base",
    "BaseNumber",
    "Load",
    "Mass",
    "CenterOfMass",
];

/// KUKA's tools and bases (`TOOL_DATA[16]`, `BASE_DATA[32]` in `$CONFIG.DAT`, KSS 8).
pub const TOOLS: u8 = 16;
pub const BASES: u8 = 32;

/// The heaviest load taken (kg): the largest robots carry 2,300 kg; more is a unit mistake.
const MAX_MASS: f64 = 10_000.0;
/// The farthest a frame may be from its origin (mm): 1 km is a unit mistake.
const MAX_LENGTH: f64 = 1_000_000.0;

/// Reads resource `r`'s tool, base and load attributes.
pub fn read(file: FileId, r: Node, element: &str, diags: &mut Diagnostics) -> Tooling {
    let mut rd = Reader {
        file,
        element,
        diags,
    };
    let attr = |names: &[&str]| names.iter().find_map(|n| caex_attr(r, n));
    Tooling {
        tool: attr(&["Tool", "TCP"]).and_then(|a| rd.frame(a, true)),
        tool_number: attr(&["ToolNumber"]).and_then(|a| rd.number(a, TOOLS, "tools")),
        base: attr(&["Base"]).and_then(|a| rd.frame(a, true)),
        base_number: attr(&["BaseNumber"]).and_then(|a| rd.number(a, BASES, "bases")),
        load: attr(&["Load"]).and_then(|a| rd.mass(a)),
        mass: attr(&["Mass"]).and_then(|a| rd.mass(a)),
        center: attr(&["CenterOfMass"])
            .and_then(|a| rd.frame(a, false))
            .map(|(f, s)| (f.xyz, s)),
    }
}

struct Reader<'d> {
    file: FileId,
    element: &'d str,
    diags: &'d mut Diagnostics,
}

/// A length unit's factor to mm, an angle unit's to degrees.
fn unit_factor(unit: &str, angle: bool) -> Option<f64> {
    let u = unit.trim().to_ascii_lowercase();
    Some(match (angle, u.as_str()) {
        (false, "" | "m" | "meter" | "metre") => 1000.0,
        (false, "mm" | "millimeter" | "millimetre") => 1.0,
        (false, "cm") => 10.0,
        (true, "" | "degree" | "degrees" | "deg" | "\u{b0}") => 1.0,
        (true, "rad" | "radian" | "radians") => 180.0 / std::f64::consts::PI,
        _ => return None,
    })
}

impl Reader<'_> {
    fn error(&mut self, span: Span, message: String) {
        self.diags.push(
            Diagnostic::error(Code::BadToolData, message)
                .at(span)
                .element(self.element.to_owned()),
        );
    }

    /// The `Value` (else the `DefaultValue`) text of `a`, trimmed, with its span; `None` when
    /// there is neither or it is empty.
    fn value(&self, a: Node) -> Option<(String, Span)> {
        ["Value", "DefaultValue"].iter().find_map(|tag| {
            let v = child(a, tag)?;
            let text: String = v.children().filter_map(|c| c.text()).collect();
            let text = text.trim();
            (!text.is_empty()).then(|| (text.to_owned(), Span::new(self.file, v.range())))
        })
    }

    /// A decimal number with `.` (an exponent allowed), finite.
    fn parse(text: &str) -> Option<f64> {
        let ok = text
            .bytes()
            .all(|b| b.is_ascii_digit() || matches!(b, b'.' | b'-' | b'+' | b'e' | b'E'));
        text.parse::<f64>().ok().filter(|x| ok && x.is_finite())
    }

    /// A frame: sub-attributes `x`, `y`, `z` (and `rx`, `ry`, `rz` when `rotation`); a missing
    /// one is 0.
    fn frame(&mut self, a: Node, rotation: bool) -> Option<(Frame, Span)> {
        let name = caex_name(a).unwrap_or("").trim().to_owned();
        let span = tag_span(self.file, a);
        let wanted: &[&str] = if rotation {
            &["x", "y", "z", "rx", "ry", "rz"]
        } else {
            &["x", "y", "z"]
        };
        let subs: Vec<Node> = children(a, "Attribute").collect();
        if subs.is_empty() {
            let what = if rotation {
                "a frame: the attributes `x`, `y`, `z` (m) and `rx`, `ry`, `rz` (degrees) inside it, as AutomationML's `Frame`"
            } else {
                "a point: the attributes `x`, `y`, `z` (m) inside it"
            };
            let hint = match (
                names::eq(&name, "Tool") || names::eq(&name, "TCP"),
                names::eq(&name, "Base"),
            ) {
                (true, _) => "; one of the controller's own tools is `ToolNumber`",
                (_, true) => "; one of the controller's own bases is `BaseNumber`",
                _ => "",
            };
            self.error(span, format!("`{name}` is {what}{hint}"));
            return None;
        }
        let mut values = [0.0f64; 6];
        let mut ok = true;
        for s in subs {
            let sub = caex_name(s).unwrap_or("").trim();
            let Some(k) = wanted.iter().position(|w| names::eq(w, sub)) else {
                let near = names::did_you_mean(sub, wanted.iter().copied());
                self.error(
                    tag_span(self.file, s),
                    format!(
                        "`{name}` has an attribute `{sub}`, which is none of {}{near}",
                        list(wanted)
                    ),
                );
                ok = false;
                continue;
            };
            let angle = k >= 3;
            let unit = s.attribute("Unit").unwrap_or("");
            let Some(factor) = unit_factor(unit, angle) else {
                let units = if angle {
                    "`degree` (the default) or `rad`"
                } else {
                    "`m` (the default), `mm` or `cm`"
                };
                self.error(
                    attr_span(self.file, s, "Unit"),
                    format!("`{name}.{sub}` has the unit `{unit}`: it can be {units}"),
                );
                ok = false;
                continue;
            };
            let Some((text, vspan)) = self.value(s) else {
                continue;
            };
            let limit = if angle { 360.0 } else { MAX_LENGTH };
            match Self::parse(&text).map(|x| x * factor) {
                Some(x) if x.abs() <= limit => values[k] = x,
                Some(_) if angle => {
                    self.error(
                        vspan,
                        format!("`{name}.{sub}` is `{text}`: an angle from -360 to 360 degrees"),
                    );
                    ok = false;
                }
                Some(_) => {
                    self.error(
                        vspan,
                        format!(
                            "`{name}.{sub}` is `{text}`: more than 1 km from the origin (AutomationML's lengths are metres)"
                        ),
                    );
                    ok = false;
                }
                None => {
                    self.error(
                        vspan,
                        format!("`{name}.{sub}` is `{text}`: a number with `.` for decimals"),
                    );
                    ok = false;
                }
            }
        }
        let [x, y, z, rx, ry, rz] = values;
        ok.then_some((
            Frame {
                xyz: [x, y, z],
                abc: [rz, ry, rx],
            },
            span,
        ))
    }

    /// A tool or base number from 1 to `max`.
    fn number(&mut self, a: Node, max: u8, what: &str) -> Option<(u8, Span)> {
        let name = caex_name(a).unwrap_or("").trim().to_owned();
        let Some((text, span)) = self.value(a) else {
            self.error(
                tag_span(self.file, a),
                format!("`{name}` has no value: a number from 1 to {max}"),
            );
            return None;
        };
        match text.parse::<u8>() {
            Ok(n) if (1..=max).contains(&n) => Some((n, span)),
            _ => {
                let array = if max == TOOLS {
                    "TOOL_DATA"
                } else {
                    "BASE_DATA"
                };
                self.error(
                    span,
                    format!(
                        "`{name}` is `{text}`: a KUKA controller has {what} 1 to {max} ({array}[1] to {array}[{max}])"
                    ),
                );
                None
            }
        }
    }

    /// A mass in kg (`Unit` `kg`, the default, or `g`), more than 0 and at most 10 t.
    fn mass(&mut self, a: Node) -> Option<(f64, Span)> {
        let name = caex_name(a).unwrap_or("").trim().to_owned();
        let (text, span) = self.value(a)?;
        let unit = a.attribute("Unit").unwrap_or("").trim();
        let factor = match unit.to_ascii_lowercase().as_str() {
            "" | "kg" => 1.0,
            "g" => 0.001,
            _ => {
                self.error(
                    attr_span(self.file, a, "Unit"),
                    format!("`{name}` has the unit `{unit}`: it can be `kg` (the default) or `g`"),
                );
                return None;
            }
        };
        match Self::parse(&text).map(|m| m * factor) {
            Some(m) if m > 0.0 && m <= MAX_MASS => Some((m, span)),
            _ => {
                self.error(
                    span,
                    format!("`{name}` is `{text}`: a mass in kg, more than 0 and at most 10000"),
                );
                None
            }
        }
    }
}

/// The `-pB` lines of a resource's tool, base and load (`(Tool) X 0, Y 0, Z 135, A 0, B 30, C 0`),
/// as the model keeps them: mm, degrees, KUKA's A-B-C.
pub fn listing(t: &Tooling) -> Vec<String> {
    let n = |x: f64| crate::convert::format_number(x).unwrap_or_default();
    let frame = |f: &Frame| {
        let [x, y, z] = f.xyz.map(n);
        let [a, b, c] = f.abc.map(n);
        format!("X {x}, Y {y}, Z {z}, A {a}, B {b}, C {c} (mm, degrees)")
    };
    let mut out = Vec::new();
    if let Some((f, _)) = &t.tool {
        out.push(format!("(Tool) {}", frame(f)));
    }
    if let Some((k, _)) = &t.tool_number {
        out.push(format!("(ToolNumber) {k}"));
    }
    if let Some((f, _)) = &t.base {
        out.push(format!("(Base) {}", frame(f)));
    }
    if let Some((k, _)) = &t.base_number {
        out.push(format!("(BaseNumber) {k}"));
    }
    if let Some((m, _)) = &t.load {
        out.push(format!("(Load) {} kg", n(*m)));
    }
    if let Some((m, _)) = &t.mass {
        out.push(format!("(Mass) {} kg", n(*m)));
    }
    if let Some((c, _)) = &t.center {
        let [x, y, z] = c.map(n);
        out.push(format!("(CenterOfMass) X {x}, Y {y}, Z {z} (mm)"));
    }
    out
}

fn list(names: &[&str]) -> String {
    let v: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    v.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_str(xml: &str) -> (Tooling, Vec<String>) {
        let doc = roxmltree::Document::parse(xml).unwrap();
        let mut d = Diagnostics::default();
        let t = read(FileId::default(), doc.root_element(), "r", &mut d);
        let msgs = d.iter().map(|d| d.message.clone()).collect();
        (t, msgs)
    }

    #[test]
    fn an_automationml_frame_in_metres_and_degrees_becomes_mm_and_kuka_angles() {
        let (t, m) = read_str(
            r#"<InternalElement Name="G">
              <Attribute Name="Tool" RefAttributeType="AutomationMLBaseAttributeTypeLib/Frame">
                <Attribute Name="x" AttributeDataType="xs:double" Unit="m"><Value>0.01</Value></Attribute>
                <Attribute Name="z" AttributeDataType="xs:double"><DefaultValue>0</DefaultValue><Value>0.12</Value></Attribute>
                <Attribute Name="rx" AttributeDataType="xs:double" Unit="degree"><Value>180</Value></Attribute>
                <Attribute Name="rz" AttributeDataType="xs:double" Unit="rad"><Value>0</Value></Attribute>
              </Attribute>
              <Attribute Name="ToolNumber"><Value>3</Value></Attribute>
              <Attribute Name="Mass" Unit="kg"><Value>1.5</Value></Attribute>
            </InternalElement>"#,
        );
        assert!(m.is_empty(), "{m:?}");
        let (f, _) = t.tool.unwrap();
        assert_eq!(f.xyz, [10.0, 0.0, 120.0]);
        assert_eq!(f.abc, [0.0, 0.0, 180.0]);
        assert_eq!(t.tool_number.unwrap().0, 3);
        assert_eq!(t.mass.unwrap().0, 1.5);
        assert!(t.base.is_none() && t.load.is_none());
    }

    #[test]
    fn values_that_cannot_be_used_are_e216_each() {
        let (t, m) = read_str(
            r#"<InternalElement Name="G">
              <Attribute Name="Tool"><Attribute Name="rxx"><Value>1</Value></Attribute></Attribute>
              <Attribute Name="Base"><Attribute Name="x" Unit="inch"><Value>1</Value></Attribute></Attribute>
              <Attribute Name="ToolNumber"><Value>17</Value></Attribute>
              <Attribute Name="BaseNumber"><Value>0</Value></Attribute>
              <Attribute Name="Load"><Value>1,5</Value></Attribute>
            </InternalElement>"#,
        );
        assert!(t.is_empty());
        assert_eq!(m.len(), 5, "{m:?}");
        assert!(m[0].contains("did you mean `rx`"), "{}", m[0]);
        assert!(m[1].contains("tools 1 to 16"), "{}", m[1]);
    }
}

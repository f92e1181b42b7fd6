//! A blackboard of a cell (docs/CELLS.md) made from a blackboard of one robot: the robot's element
//! copied once per robot `R1`, `R2`, … (each copy from its own text, so each may be in another
//! language), with IDs made unique, wire signals added to each and an `InternalLink` per wire.
//!
//! Shared by `benches/cells.rs` and the cell co-simulation of `tests/flow_run/cosim.rs`:
//! `#[path = "../../benches/common/cell.rs"] mod cell;`.
#![allow(dead_code)]

/// The element of the resource `name` in `text`: its lines from the opening tag to the closing
/// one at the same indentation, and that indentation; `None` when there is none.
pub fn robot_element<'t>(text: &'t str, name: &str) -> Option<(usize, usize, &'t str)> {
    let lines: Vec<&str> = text.lines().collect();
    let opening = format!("<InternalElement Name=\"{name}\"");
    let start = lines.iter().position(|l| l.contains(&opening))?;
    let indent = &lines[start][..lines[start].len() - lines[start].trim_start().len()];
    let end = start
        + lines[start..]
            .iter()
            .position(|l| *l == format!("{indent}</InternalElement>"))?;
    Some((start, end, indent))
}

/// A signal's address attribute: `("Number", "12")` or `("Address", "do_Ready")`.
pub type Attr = (&'static str, String);

/// A cell of `n` robots with `m` wires from each to each other. `single(k)` is the one-robot
/// blackboard for robot `k` (from 1; its resource named `robot`); robot 1's gives everything
/// around the robots. `wire(k, p, j)` gives the attribute (`Number` or `Address`, with its
/// value) of robot `k`'s output `To_R<p>_<j>` and of its input `From_R<p>_<j>`. The robot's
/// `refURI`s are changed by `irl(k, value)`.
pub fn cell_blackboard(
    robot: &str,
    n: usize,
    m: usize,
    single: &dyn Fn(usize) -> String,
    wire: &dyn Fn(usize, usize, usize) -> (Attr, Attr),
    irl: &dyn Fn(usize, &str) -> String,
) -> String {
    let frame = single(1);
    let (start, end, indent) = robot_element(&frame, robot).expect("the robot's element");
    let lines: Vec<&str> = frame.lines().collect();
    let mut out: Vec<String> = lines[..start].iter().map(|s| s.to_string()).collect();
    let id = |k: usize| format!("{{00000000-0000-0000-{k:04}-000000000002}}");
    let signal = |k: usize, name: &str, io: &str, (attr, value): Attr| {
        let ty = if attr == "Number" {
            "xs:integer"
        } else {
            "xs:string"
        };
        format!(
            "\n{indent}  <ExternalInterface Name=\"{name}\" ID=\"{{w-{k}-{name}}}\" RefBaseClassPath=\"AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface\"><Attribute Name=\"IoType\" AttributeDataType=\"xs:string\"><Value>{io}</Value></Attribute><Attribute Name=\"{attr}\" AttributeDataType=\"{ty}\"><Value>{value}</Value></Attribute></ExternalInterface>"
        )
    };
    for k in 1..=n {
        let own = single(k);
        let (s, e, _) = robot_element(&own, robot).expect("the robot's element");
        let own_lines: Vec<&str> = own.lines().collect();
        let mut text = own_lines[s..=e]
            .join("\n")
            .replacen(&format!("Name=\"{robot}\""), &format!("Name=\"R{k}\""), 1)
            .replace(
                "{00000000-0000-0000-0000-",
                &format!("{{00000000-0000-0000-{k:04}-"),
            );
        text = irl(k, &text);
        let mut wires = String::new();
        for p in (1..=n).filter(|&p| p != k) {
            for j in 1..=m {
                let (o, i) = wire(k, p, j);
                wires.push_str(&signal(k, &format!("To_R{p}_{j}"), "Output", o));
                wires.push_str(&signal(k, &format!("From_R{p}_{j}"), "Input", i));
            }
        }
        // After the element's own attributes (CAEX: attributes come first).
        let mut at = text.find('\n').unwrap();
        while text[at + 1..].trim_start().starts_with("<Attribute ") {
            at += 1 + text[at + 1..].find('\n').unwrap();
        }
        text.insert_str(at, &wires);
        out.push(text);
    }
    for a in 1..=n {
        for b in (1..=n).filter(|&b| b != a) {
            for j in 1..=m {
                out.push(format!(
                    "{indent}<InternalLink Name=\"R{a} to R{b} {j}\" RefPartnerSideA=\"{}:To_R{b}_{j}\" RefPartnerSideB=\"{}:From_R{a}_{j}\"/>",
                    id(a),
                    id(b)
                ));
            }
        }
    }
    out.extend(lines[end + 1..].iter().map(|s| s.to_string()));
    out.join("\n")
}

/// Puts each step of a generated chart (`generator.rs`, on `KUKA KR15-2`) on one of `n` robots
/// `R1`…, in runs of 1 to 20 steps (a fixed sequence).
pub fn spread(sfc: &str, n: usize) -> String {
    let marker = "<ressource name=\"KUKA KR15-2\"/>";
    let mut out = String::with_capacity(sfc.len());
    let (mut rest, mut seed, mut left, mut robot) = (sfc, 0x9E37_79B9_7F4A_7C15u64, 0u64, 0u64);
    while let Some(at) = rest.find(marker) {
        if left == 0 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            left = 1 + seed % 20;
            robot = (robot + 1 + (seed >> 8) % (n as u64 - 1)) % n as u64;
        }
        left -= 1;
        out.push_str(&rest[..at]);
        out.push_str(&format!("<ressource name=\"R{}\"/>", robot + 1));
        rest = &rest[at + marker.len()..];
    }
    out.push_str(rest);
    out
}

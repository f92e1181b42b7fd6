//! The listings as JSON objects, for `--format json` (one object per listing, printed on one
//! line; docs/JSON.md). Each has `"listing"`: `blackboard`, `sfc`, `flow` or `order`.

use serde_json::{Value as Json, json};

use super::{Totals, condition, duration, one_line, signal_text, step_name};
use crate::model::{Blackboard, ElementKind, Sfc, SignalKind, Value};
use crate::plan::{Block, BranchEnd, Plan};

/// `-pB`: resources with their skills (and the calls each maps), functions and signals.
pub fn blackboard(
    bb: &Blackboard,
    languages: &std::collections::HashMap<usize, crate::lang::Language>,
    uses: Option<&std::collections::HashMap<usize, String>>,
) -> Json {
    let resources: Vec<Json> = bb
        .resources
        .iter()
        .enumerate()
        .map(|(ri, r)| {
            let mut skills: Vec<_> = r.skills.iter().collect();
            skills.sort_by(|a, b| a.name.key.cmp(&b.name.key));
            let skills: Vec<Json> = skills
                .iter()
                .map(|s| {
                    let calls: Vec<Json> = s
                        .mappings
                        .iter()
                        .map(|m| {
                            json!({
                                "function": &*m.function.text,
                                "arguments": m.args.iter().map(|a| &*a.skill_param.text).collect::<Vec<_>>(),
                                "order": m.order,
                            })
                        })
                        .collect();
                    json!({"name": &*s.name.text, "id": s.id, "calls": calls})
                })
                .collect();
            let mut funcs: Vec<_> = r.functions.iter().collect();
            funcs.sort_by(|a, b| a.name.key.cmp(&b.name.key));
            let functions: Vec<Json> = funcs
                .iter()
                .map(|f| {
                    json!({
                        "name": &*f.name.text,
                        "id": f.id,
                        "irl": f.irl.value,
                        "command": &*f.command.text,
                    })
                })
                .collect();
            let signals: Vec<Json> = r
                .signals
                .iter()
                .map(|s| {
                    let mut o = json!({
                        "name": &*s.name.text,
                        "direction": if s.output { "output" } else { "input" },
                        "type": if s.is_integer() { "integer" } else { "bit" },
                    });
                    match &s.kind {
                        SignalKind::Bit(n) => o["number"] = json!(n),
                        SignalKind::Group { number, length } => {
                            o["number"] = json!(number);
                            o["length"] = json!(length);
                        }
                        SignalKind::Address { text, .. } => o["address"] = json!(text),
                    }
                    o["text"] = json!(signal_text(s));
                    o
                })
                .collect();
            let language = languages
                .get(&ri)
                .copied()
                .or(r.language.as_ref().map(|(l, _)| *l));
            let controller = bb.controller_of(ri);
            json!({
                "name": &*r.name.text,
                "id": r.id,
                "controller": &*bb.resources[controller].name.text,
                "controller_description": r.controller_attr.as_ref()
                    .filter(|_| controller == ri)
                    .map(|(v, _)| v),
                "language": language.map(|l| l.name()),
                "language_from": match (languages.get(&ri), &r.language) {
                    (_, Some(_)) => "attribute",
                    (Some(_), None) => "irl-or-default",
                    (None, None) => "unknown",
                },
                "skills": skills,
                "functions": functions,
                "signals": signals,
            })
        })
        .collect();
    let wires: Vec<Json> = bb
        .wires
        .iter()
        .enumerate()
        .map(|(k, w)| {
            let end = |(r, si): (usize, usize)| {
                json!({
                    "resource": &*bb.resources[r].name.text,
                    "controller": &*bb.resources[bb.controller_of(r)].name.text,
                    "signal": &*bb.resources[r].signals[si].name.text,
                })
            };
            json!({
                "name": w.name,
                "from": end(w.from),
                "to": end(w.to),
                "handshake": uses.and_then(|u| u.get(&k)),
            })
        })
        .collect();
    json!({"listing": "blackboard", "resources": resources, "wires": wires})
}

fn value(v: &Value) -> Json {
    match v {
        Value::Scalar(s) => json!(s),
        Value::List(items) => Json::Array(items.iter().map(value).collect()),
    }
}

/// `-pS`: the file header, the POU, and every SFC object with its connections.
pub fn sfc(sfc: &Sfc) -> Json {
    let h = &sfc.header;
    let mut succs: std::collections::HashMap<u64, Vec<u64>> = Default::default();
    for e in &sfc.elements {
        for (r, _) in &e.inputs {
            succs.entry(*r).or_default().push(e.local_id);
        }
    }
    let objects: Vec<Json> = sfc
        .elements
        .iter()
        .map(|e| {
            let mut o = json!({
                "kind": e.kind.tag(),
                "local_id": e.local_id,
                "inputs": e.inputs.iter().map(|(r, _)| *r).collect::<Vec<_>>(),
                "outputs": succs.get(&e.local_id).cloned().unwrap_or_default(),
            });
            match &e.kind {
                ElementKind::Step(st) => {
                    o["name"] = json!(&*st.name);
                    o["initial"] = json!(st.initial);
                    o["duration"] = json!(st.duration.unwrap_or(0.0));
                    o["resource"] = json!(st.resource.as_ref().map(|r| &*r.text));
                    o["skill"] = json!(st.skill.as_ref().map(|s| &*s.text));
                    o["variables"] = Json::Array(
                        sfc.variables_of(st)
                            .iter()
                            .map(|v| json!({"name": &*v.name.text, "value": value(&sfc.value_of(v))}))
                            .collect(),
                    );
                }
                ElementKind::Transition(c) => {
                    o["condition"] = json!(
                        c.as_ref()
                            .map_or_else(|| "TRUE".to_owned(), |c| one_line(&c.text))
                    );
                    o["reference"] = json!(c.as_ref().is_some_and(|c| c.reference));
                }
                ElementKind::JumpStep(t) => {
                    o["target"] = json!(t.as_ref().map(|t| &*t.text));
                }
                _ => {}
            }
            o
        })
        .collect();
    json!({
        "listing": "sfc",
        "header": {
            "company_name": h.company_name,
            "product_name": h.product_name,
            "product_version": h.product_version,
            "creation_date_time": h.creation_date_time,
        },
        "pou": sfc.pou_name,
        "objects": objects,
    })
}

fn local_id(sfc: &Sfc, i: usize) -> u64 {
    sfc.elements[i].local_id
}

/// `-pF`: the flow as a tree of blocks with start times and durations (seconds), and the
/// total. Times are counted as in the text listing.
pub fn flow(sfc: &Sfc, plan: &Plan) -> Json {
    fn walk(sfc: &Sfc, blocks: &[Block], t: f64, tot: &mut Totals) -> (Vec<Json>, f64) {
        let mut t = t;
        let mut out = Vec::new();
        for b in blocks {
            match b {
                // Handshakes stand only in the programs of a cell, not in the chart's plan.
                Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => {}
                Block::Step(i) => {
                    let d = duration(sfc, *i);
                    out.push(json!({
                        "kind": "step",
                        "local_id": local_id(sfc, *i),
                        "name": step_name(sfc, *i),
                        "start": t,
                        "duration": d,
                    }));
                    t += d;
                }
                Block::Wait(tr) => out.push(json!({
                    "kind": "wait",
                    "condition": condition(sfc, *tr),
                    "transition": local_id(sfc, *tr),
                })),
                Block::Machine(states) => {
                    tot.states = true;
                    let mut ss = Vec::new();
                    for st in states {
                        let (blocks, e) = walk(sfc, &st.body, t, tot);
                        t = e;
                        ss.push(json!({"entry": local_id(sfc, st.entry), "blocks": blocks}));
                    }
                    out.push(json!({"kind": "states", "states": ss}));
                }
                Block::Goto { target, .. } => out.push(json!({
                    "kind": "goto",
                    "target": local_id(sfc, *target),
                })),
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    // All start together; the block ends with the longest.
                    let start = t;
                    let mut end = t;
                    let mut bs = Vec::new();
                    for br in branches {
                        let (blocks, e) = walk(sfc, br, start, tot);
                        end = end.max(e);
                        bs.push(json!({"blocks": blocks}));
                    }
                    out.push(match b {
                        Block::Parallel { divergence, .. } => json!({
                            "kind": "parallel",
                            "divergence": local_id(sfc, *divergence),
                            "start": start,
                            "end": end,
                            "branches": bs,
                        }),
                        _ => json!({
                            "kind": "sequences",
                            "start": start,
                            "end": end,
                            "sequences": bs,
                        }),
                    });
                    t = end;
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                } => {
                    tot.choices = true;
                    let start = t;
                    let mut end = t;
                    let mut bs = Vec::new();
                    for br in branches {
                        let (blocks, e) = walk(sfc, &br.body, start, tot);
                        end = end.max(e);
                        let mut o = json!({
                            "condition": br.condition_text(sfc),
                            "transition": local_id(sfc, br.transition),
                            "blocks": blocks,
                        });
                        match br.end {
                            BranchEnd::Join => o["then"] = json!("join"),
                            BranchEnd::Repeat(j) => {
                                o["then"] = json!("repeat");
                                o["jump"] = json!(local_id(sfc, j));
                            }
                            BranchEnd::Leave => o["then"] = json!("leave"),
                        }
                        bs.push(o);
                    }
                    out.push(json!({
                        "kind": "selection",
                        "divergence": local_id(sfc, *divergence),
                        "start": start,
                        "end": end,
                        "branches": bs,
                    }));
                    t = end;
                }
                Block::Loop {
                    head,
                    body,
                    endless,
                    ..
                } => {
                    tot.loops = true;
                    tot.endless |= *endless;
                    let start = t;
                    let (blocks, e) = walk(sfc, body, t, tot);
                    out.push(json!({
                        "kind": "loop",
                        "head": local_id(sfc, *head),
                        "endless": endless,
                        "start": start,
                        "end": e,
                        "blocks": blocks,
                    }));
                    t = e;
                }
            }
        }
        (out, t)
    }
    let mut tot = Totals::default();
    let (blocks, total) = walk(sfc, &plan.body, 0.0, &mut tot);
    json!({
        "listing": "flow",
        "blocks": blocks,
        "total": {
            "seconds": total,
            "at_least": (tot.loops || tot.states) && !tot.endless,
            "per_round": tot.endless,
            "longest_alternative": tot.choices,
        },
    })
}

/// `-pO`: the execution order as a tree of blocks.
pub fn order(sfc: &Sfc, plan: &Plan) -> Json {
    let mut blocks = Vec::new();
    let mut n = 0;
    order_blocks(sfc, None, &plan.body, &mut n, &mut blocks);
    json!({"listing": "order", "steps": n, "blocks": blocks})
}

/// The blocks of `-pO`; with a cell's view, a program's handshakes too (`tell`, `hear`,
/// and `decided_by` of a selection it follows).
fn order_blocks(
    sfc: &Sfc,
    view: Option<&super::CellView>,
    blocks: &[Block],
    n: &mut usize,
    out: &mut Vec<Json>,
) {
    for b in blocks {
        match b {
            Block::Step(i) => {
                *n += 1;
                out.push(json!({
                    "kind": "step",
                    "number": *n,
                    "local_id": local_id(sfc, *i),
                    "name": step_name(sfc, *i),
                }));
            }
            Block::Wait(t) => out.push(json!({
                "kind": "wait",
                "condition": condition(sfc, *t),
                "transition": local_id(sfc, *t),
            })),
            Block::Machine(states) => {
                let mut ss = Vec::new();
                for st in states {
                    let mut blocks = Vec::new();
                    order_blocks(sfc, view, &st.body, n, &mut blocks);
                    ss.push(json!({"entry": local_id(sfc, st.entry), "blocks": blocks}));
                }
                out.push(json!({"kind": "states", "states": ss}));
            }
            Block::Goto { target, .. } => out.push(json!({
                "kind": "goto",
                "target": local_id(sfc, *target),
            })),
            Block::Tell(m) | Block::Hear(m) => {
                let Some(view) = view else {
                    continue;
                };
                let tell = matches!(b, Block::Tell(_));
                let ch = &view.cell.channels[m.channel];
                let decision = m.kind == crate::plan::cell::Kind::Decision;
                out.push(json!({
                    "kind": if tell { "tell" } else { "hear" },
                    "controller": view.controller(if tell { ch.to } else { ch.from }),
                    "about": local_id(sfc, m.about),
                    "decision": decision,
                    "branch": (tell && decision).then_some(m.value + 1),
                    "passed": match m.kind {
                        crate::plan::cell::Kind::Passed(c) => Some(c.name()),
                        _ => None,
                    },
                }));
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    order_blocks(sfc, view, br, n, out);
                }
            }
            Block::Choice {
                divergence,
                branches,
                ..
            }
            | Block::Follow {
                divergence,
                branches,
                ..
            } => {
                let bs: Vec<Json> = branches
                    .iter()
                    .map(|br| {
                        let mut blocks = Vec::new();
                        order_blocks(sfc, view, &br.body, n, &mut blocks);
                        json!({
                            "condition": br.condition_text(sfc),
                            "transition": local_id(sfc, br.transition),
                            "blocks": blocks,
                            "then": match br.end {
                                BranchEnd::Join => "join",
                                BranchEnd::Repeat(_) => "repeat",
                                BranchEnd::Leave => "leave",
                            },
                        })
                    })
                    .collect();
                let mut selection = json!({
                    "kind": "selection",
                    "divergence": local_id(sfc, *divergence),
                });
                if let Some(v) = view {
                    selection["decided_by"] = match b {
                        Block::Follow { heard, .. } => {
                            json!(v.controller(v.cell.channels[heard.channel].from))
                        }
                        _ => Json::Null,
                    };
                }
                selection["branches"] = Json::Array(bs);
                out.push(selection);
            }
            Block::Loop {
                head,
                body,
                endless,
                ..
            } => {
                let mut blocks = Vec::new();
                order_blocks(sfc, view, body, n, &mut blocks);
                out.push(json!({
                    "kind": "loop",
                    "head": local_id(sfc, *head),
                    "endless": endless,
                    "blocks": blocks,
                }));
            }
        }
    }
}

/// A listing that cannot be printed (`-pF`/`-pO` when the flow has errors).
pub fn unavailable(listing: &str, reason: &str) -> Json {
    json!({"listing": listing, "available": false, "reason": reason})
}

/// `-pO` of a cell: each program with its blocks, handshakes included (`tell`, `hear`, a
/// selection it follows, `decided_by` its decider).
pub fn cell_order(sfc: &Sfc, view: &super::CellView) -> Json {
    let mut total = 0;
    let programs: Vec<Json> = view
        .cell
        .programs
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let mut blocks = Vec::new();
            let mut n = 0;
            order_blocks(sfc, Some(view), &p.body, &mut n, &mut blocks);
            total += n;
            json!({
                "program": view.names.get(k),
                "controller": view.controller(k),
                "steps": n,
                "blocks": blocks,
            })
        })
        .collect();
    json!({"listing": "order", "steps": total, "programs": programs})
}

/// `-pF` of a cell: one lane per controller with its steps and its waits for others, and
/// the cell's time.
pub fn cell_flow(sfc: &Sfc, plan: &Plan, view: &super::CellView) -> Json {
    let (lanes, total) = super::cell_timeline(sfc, plan, view);
    let lanes: Vec<Json> = lanes
        .iter()
        .enumerate()
        .map(|(k, lane)| {
            let items: Vec<Json> = lane
                .iter()
                .map(|it| match it.waits_for {
                    Some(c) => json!({
                        "kind": "wait",
                        "start": it.start,
                        "end": it.end,
                        "for_controller": view.controller(c),
                        "for_step": local_id(sfc, it.element),
                    }),
                    None => json!({
                        "kind": "step",
                        "start": it.start,
                        "duration": it.end - it.start,
                        "local_id": local_id(sfc, it.element),
                        "name": step_name(sfc, it.element),
                    }),
                })
                .collect();
            json!({
                "controller": view.controller(k),
                "program": view.names.get(k),
                "items": items,
            })
        })
        .collect();
    json!({"listing": "flow", "lanes": lanes, "total": total})
}

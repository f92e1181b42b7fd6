//! Charts drawn as closed circles (docs/INPUTS.md): Beremiz and OpenPLC draw a sequence loop as a
//! connection from the last transition back to an earlier step (or to the selection convergence
//! right before it), not as a jumpStep. Such a connection is a loop like a jump to that step:
//! before planning, [`close_circles`] takes each one out of the inputs it stands in and adds a
//! jumpStep naming the step, connected to where the connection came from (`Sfc::closed` keeps
//! what was changed). A cycle that passes through no step stays, for the cycle check.

use crate::diag::Span;
use crate::model::{Closed, Element, ElementKind, Inputs, Name, Sfc};

/// Whether every connection comes from an element of a smaller localId. Then the ids ascend
/// along every path, no connection closes a cycle, and [`close_circles`] has nothing to do: one
/// pass over the elements (charts are usually numbered so) instead of building their graph.
fn all_forward(sfc: &Sfc) -> bool {
    sfc.elements
        .iter()
        .all(|e| e.inputs.iter().all(|(r, _)| *r < e.local_id))
}

/// Makes every connection back to an earlier step a jump; returns how many there were.
/// "Earlier": the connection closes a cycle of the depth-first walk from the start steps (the
/// steps marked `initialStep="true"` and those without a predecessor), and leads into a step
/// or into a selection convergence whose one successor is a step.
pub fn close_circles(sfc: &mut Sfc) -> usize {
    if all_forward(sfc) {
        return 0;
    }
    let n = sfc.elements.len();
    let mut ids = super::graph::Ids::new(sfc);
    for (i, e) in sfc.elements.iter().enumerate() {
        if ids.get(e.local_id).is_none() {
            ids.insert(e.local_id, i);
        }
    }
    // Successors, flat: element `p`'s are `succ[start[p]..start[p + 1]]` (one allocation for
    // the chart, not one per element: 100,000 steps).
    let mut edges: Vec<(usize, usize)> = Vec::with_capacity(n + n / 4);
    for (i, e) in sfc.elements.iter().enumerate() {
        for (r, _) in &e.inputs {
            if let Some(p) = ids.get(*r) {
                edges.push((p, i));
            }
        }
    }
    drop(ids);
    // By producer, each producer's consumers in the order they came (a stable sort), each once.
    edges.sort_by_key(|e| e.0);
    edges.dedup();
    let mut start = vec![0usize; n + 1];
    for &(p, _) in &edges {
        start[p + 1] += 1;
    }
    for k in 0..n {
        start[k + 1] += start[k];
    }
    let succ_of: Vec<usize> = edges.iter().map(|e| e.1).collect();
    let succ = |p: usize| &succ_of[start[p]..start[p + 1]];
    let roots: Vec<usize> = (0..n)
        .filter(|&i| match &sfc.elements[i].kind {
            ElementKind::Step(st) => st.initial || matches!(sfc.elements[i].inputs, Inputs::None),
            _ => false,
        })
        .collect();
    // Iterative depth-first walk: 0 not seen, 1 on the path, 2 done.
    let mut color = vec![0u8; n];
    let mut back: Vec<(usize, usize)> = Vec::new();
    for &root in &roots {
        if color[root] != 0 {
            continue;
        }
        let mut stack: Vec<(usize, usize)> = vec![(root, 0)];
        color[root] = 1;
        while let Some(&mut (u, ref mut k)) = stack.last_mut() {
            if let Some(&v) = succ(u).get(*k) {
                *k += 1;
                match color[v] {
                    0 => {
                        color[v] = 1;
                        stack.push((v, 0));
                    }
                    1 => back.push((u, v)),
                    _ => {}
                }
            } else {
                color[u] = 2;
                stack.pop();
            }
        }
    }
    let mut next_id = sfc.elements.iter().map(|e| e.local_id).max().unwrap_or(0);
    let mut made = 0;
    for (u, v) in back {
        let target = match &sfc.elements[v].kind {
            ElementKind::Step(_) => v,
            ElementKind::SelectionConvergence => match succ(v) {
                [s] if sfc.elements[*s].kind.is_step() => *s,
                _ => continue,
            },
            _ => continue,
        };
        let ElementKind::Step(step) = &sfc.elements[target].kind else {
            continue;
        };
        let name = step.name.clone();
        let from_id = sfc.elements[u].local_id;
        // The connection out of `v`'s inputs.
        let inputs: Vec<(u64, std::ops::Range<usize>)> =
            sfc.elements[v].inputs.iter().cloned().collect();
        let Some(pos) = inputs.iter().position(|(r, _)| *r == from_id) else {
            continue;
        };
        let place = inputs[pos].1.clone();
        let rest: Vec<(u64, std::ops::Range<usize>)> = inputs
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != pos)
            .map(|(_, x)| x.clone())
            .collect();
        if v != target && rest.len() == 1 {
            // A convergence left with one branch is no convergence: the step takes its input,
            // and the convergence becomes the jump (no element is added).
            let v_id = sfc.elements[v].local_id;
            let step_inputs: Vec<(u64, std::ops::Range<usize>)> = sfc.elements[target]
                .inputs
                .iter()
                .map(|(r, range)| {
                    if *r == v_id {
                        (rest[0].0, range.clone())
                    } else {
                        (*r, range.clone())
                    }
                })
                .collect();
            sfc.elements[target].inputs = Inputs::from(step_inputs.as_slice());
            let span = sfc.elements[v].span.clone();
            sfc.elements[v].kind = ElementKind::JumpStep(Some(Box::new(Name::new(&name, span))));
            sfc.elements[v].inputs = Inputs::One((from_id, place));
            sfc.closed.push(Closed {
                jump: v,
                target,
                from: u,
            });
            made += 1;
            continue;
        }
        sfc.elements[v].inputs = Inputs::from(rest.as_slice());
        next_id += 1;
        let span = Span::new(sfc.file, place.clone());
        sfc.elements.push(Element {
            local_id: next_id,
            kind: ElementKind::JumpStep(Some(Box::new(Name::new(&name, span.clone())))),
            span,
            x: sfc.elements[u].x,
            inputs: Inputs::One((from_id, place)),
        });
        sfc.closed.push(Closed {
            jump: sfc.elements.len() - 1,
            target,
            from: u,
        });
        made += 1;
    }
    made
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diag::{Diagnostics, Sources};

    fn read(body: &str) -> Sfc {
        let text = format!(
            "<project><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>{body}</SFC></body></pou></pous></types></project>"
        );
        let mut sources = Sources::default();
        let f = sources.add("s.xml".into(), "s.xml".into(), text, false);
        crate::read::sfc::read_sfc(&sources, f, &mut Diagnostics::default()).expect("readable")
    }

    fn step(id: u64, name: &str, inputs: &[u64]) -> String {
        let conns: String = inputs
            .iter()
            .map(|r| format!("<connection refLocalId=\"{r}\"/>"))
            .collect();
        let input = if inputs.is_empty() {
            String::new()
        } else {
            format!("<connectionPointIn>{conns}</connectionPointIn>")
        };
        // The first step is the initial one.
        let initial = if name == "A" {
            " initialStep=\"true\""
        } else {
            ""
        };
        format!("<step localId=\"{id}\" name=\"{name}\"{initial}>{input}</step>")
    }

    fn transition(id: u64, input: u64) -> String {
        format!(
            "<transition localId=\"{id}\"><connectionPointIn><connection refLocalId=\"{input}\"/></connectionPointIn><condition><inline><ST>TRUE</ST></inline></condition></transition>"
        )
    }

    #[test]
    fn a_connection_back_is_closed_in_any_order_of_ids_and_elements() {
        // Drawn in order: the last transition (4) leads back into the first step (1).
        let mut sfc = read(
            &[
                step(1, "A", &[4]),
                transition(2, 1),
                step(3, "B", &[2]),
                transition(4, 3),
            ]
            .concat(),
        );
        assert!(!all_forward(&sfc));
        assert_eq!(close_circles(&mut sfc), 1);
        assert_eq!(sfc.closed.len(), 1);
        // Numbered backwards: every connection comes from a larger id, and the circle is found.
        let mut sfc = read(
            &[
                step(9, "A", &[6]),
                transition(8, 9),
                step(7, "B", &[8]),
                transition(6, 7),
            ]
            .concat(),
        );
        assert!(!all_forward(&sfc));
        assert_eq!(close_circles(&mut sfc), 1);
    }

    #[test]
    fn a_chart_numbered_forward_is_left_as_it_is_whatever_its_element_order() {
        // Listed out of order, each connection from a smaller id: no cycle, nothing changes.
        let body = [
            transition(4, 3),
            step(3, "B", &[2]),
            step(1, "A", &[]),
            transition(2, 1),
        ]
        .concat();
        let mut sfc = read(&body);
        assert!(all_forward(&sfc));
        let before: Vec<_> = sfc.elements.iter().map(|e| e.inputs.to_vec()).collect();
        assert_eq!(close_circles(&mut sfc), 0);
        let after: Vec<_> = sfc.elements.iter().map(|e| e.inputs.to_vec()).collect();
        assert_eq!(before, after);
        assert!(sfc.closed.is_empty());
    }
}

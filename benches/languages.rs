//! The 100k-step compile in each robot language (`harness = false`), issue 12's budget: no
//! language more than 10 % slower per step than KRL.
//!
//! ```text
//! cargo bench --bench languages             # 100k steps, flat and looped with selections
//! cargo bench --bench languages -- 10k      # a smaller size: 10k
//! ```
//!
//! Each case is the generator's project (`benches/common/generator.rs`) made into a project of
//! the language: the resource gets `Language`, the IRL file the language's moves (RAPID
//! robtargets with `quat(A, B, C)`, URScript poses with `m()` and `rotvec(A, B, C)`, so the
//! conversions are paid for), RAPID's signals an `Address`. Then `compile::compile` +
//! `compile::apply` into a fresh folder, median of the runs, per step and against KRL.

use std::path::Path;
use std::time::{Duration, Instant};

use skillpost::compile::{self, Options};
use skillpost::load::FsSource;

#[path = "common/generator.rs"]
mod generator;

use generator::Spec;

const RAPID_IRL: &str = "<irl>
\t<info name=\"ABB\" language=\"RAPID\"/>
\t<def>
\t\t<definition name=\"SetVelCP\">
\t\t\tPROC SetVelCP(num value)
\t\t\t  VelSet 100, value * 1000;
\t\t\tENDPROC
\t\t</definition>
\t</def>
\t<src>
\t\t<function-call name=\"SetVelCP\"><parameter name=\"VALUE\"/>SetVelCP VALUE;</function-call>
\t\t<function-call name=\"PTP\"><parameter name=\"X\"/><parameter name=\"Y\"/><parameter name=\"Z\"/><parameter name=\"A\"/><parameter name=\"B\"/><parameter name=\"C\"/>MoveJ [[X, Y, Z], [quat(A, B, C)], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v1000, z50, tool0;</function-call>
\t\t<function-call name=\"LIN\"><parameter name=\"X\"/><parameter name=\"Y\"/><parameter name=\"Z\"/><parameter name=\"A\"/><parameter name=\"B\"/><parameter name=\"C\"/>MoveL [[X, Y, Z], [quat(A, B, C)], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v200, fine, tool0;</function-call>
\t</src>
</irl>
";

const UR_IRL: &str = "<irl>
\t<info name=\"UR\" language=\"URScript\"/>
\t<def>
\t\t<definition name=\"SetVelCP\">
\t\t\tdef SetVelCP(value):
\t\t\t  global skp_v = value
\t\t\tend
\t\t</definition>
\t</def>
\t<src>
\t\t<function-call name=\"SetVelCP\"><parameter name=\"VALUE\"/>SetVelCP(VALUE)</function-call>
\t\t<function-call name=\"PTP\"><parameter name=\"X\"/><parameter name=\"Y\"/><parameter name=\"Z\"/><parameter name=\"A\"/><parameter name=\"B\"/><parameter name=\"C\"/>movej(p[m(X), m(Y), m(Z), rotvec(A, B, C)], a=1.4, v=1.05)</function-call>
\t\t<function-call name=\"LIN\"><parameter name=\"X\"/><parameter name=\"Y\"/><parameter name=\"Z\"/><parameter name=\"A\"/><parameter name=\"B\"/><parameter name=\"C\"/>movel(p[m(X), m(Y), m(Z), rotvec(A, B, C)], a=1.2, v=0.25)</function-call>
\t</src>
</irl>
";

/// Makes the generated KRL project one of `lang` (`KRL` leaves it).
fn localise(p: &generator::Project, lang: &str) {
    if lang == "KRL" {
        return;
    }
    let mut bb = std::fs::read_to_string(&p.blackboard).unwrap();
    let at = bb.find("<InternalElement Name=\"KUKA KR15-2\"").unwrap();
    let end = at + bb[at..].find('>').unwrap() + 1;
    bb.insert_str(
        end,
        &format!("\n        <Attribute Name=\"Language\"><Value>{lang}</Value></Attribute>"),
    );
    if lang == "RAPID" {
        for (n, name) in [("1", "di_PartOK"), ("2", "di_MagazineEmpty")] {
            bb = bb.replacen(
                &format!("<Attribute Name=\"Number\" AttributeDataType=\"xs:integer\"><Value>{n}</Value></Attribute>"),
                &format!("<Attribute Name=\"Address\"><Value>{name}</Value></Attribute>"),
                1,
            );
        }
    }
    std::fs::write(&p.blackboard, bb).unwrap();
    let irl = if lang == "RAPID" { RAPID_IRL } else { UR_IRL };
    std::fs::write(&p.irl, irl).unwrap();
}

fn run(bb: &Path, out_dir: &Path) -> Duration {
    let t = Instant::now();
    let c = compile::compile(
        &FsSource::default(),
        bb,
        &Options {
            program: Some("p".into()),
            ..Default::default()
        },
    );
    assert!(
        !c.has_errors(),
        "{:?}",
        c.diagnostics.iter().take(3).collect::<Vec<_>>()
    );
    // Written into a folder of its own, so every run writes (nothing is "unchanged").
    let mut c = c;
    for (p, _) in &mut c.outputs {
        *p = out_dir.join(p.file_name().unwrap());
    }
    c.write_back = None;
    compile::apply(&c).unwrap();
    t.elapsed()
}

fn median(v: &mut [Duration]) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let steps = if args.iter().any(|a| a == "10k") {
        10_000
    } else {
        100_000
    };
    let runs = 5;
    let shapes = [
        ("flat", Spec::flat(steps)),
        (
            "looped, a selection every 50",
            Spec {
                select_every: 50,
                looped: true,
                ..Spec::flat(steps)
            },
        ),
    ];
    println!(
        "| {steps} steps | language | compile + write, median of {runs} | per step | vs KRL |"
    );
    println!("|---|---|---|---|---|");
    for (shape, spec) in shapes {
        let mut krl = None;
        for lang in ["KRL", "RAPID", "URScript"] {
            let tmp = tempfile::tempdir().unwrap();
            let p = generator::write_project(&tmp.path().join("p"), &spec).unwrap();
            localise(&p, lang);
            let out = tmp.path().join("out");
            std::fs::create_dir(&out).unwrap();
            run(&p.blackboard, &out); // warm-up
            let mut times: Vec<Duration> = (0..runs).map(|_| run(&p.blackboard, &out)).collect();
            let m = median(&mut times);
            let per_step = m.as_secs_f64() * 1e9 / steps as f64;
            let base = *krl.get_or_insert(per_step);
            println!(
                "| {shape} | {lang} | {:.0} ms | {:.0} ns | {:.2}x |",
                m.as_secs_f64() * 1e3,
                per_step,
                per_step / base
            );
        }
    }
}

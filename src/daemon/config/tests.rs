use super::*;
use std::fs;

fn file() -> PathBuf {
    PathBuf::from("/etc/skillpost/skillpost.toml")
}

fn err(text: &str) -> ConfigError {
    parse(text, &file()).expect_err("should be rejected")
}

fn spec(path: &Path) -> ProjectSpec {
    ProjectSpec {
        path: path.to_path_buf(),
        ..ProjectSpec::default()
    }
}

fn root_paths(c: &Config) -> Vec<PathBuf> {
    c.roots.iter().map(|r| r.path.clone()).collect()
}

fn root(path: &str) -> RootSpec {
    RootSpec {
        path: path.into(),
        ..RootSpec::default()
    }
}

#[test]
fn valid_file_with_all_keys() {
    let text = r#"
events = "/var/log/skillpost/events.jsonl"
settle_ms = 250
allow_outside = true
max_file_size_mb = 64
forget_after_s = 120

[[project]]
path = "/srv/cells/Zelle_A"
blackboard = "Zelle_A.aml"
program = "ZELLE_A"

[[project]]
path = "/srv/cells/Zelle_B"

[[root]]
path = "/srv/planning/projects"
"#;
    let c = parse(text, &file()).unwrap();
    assert_eq!(
        c,
        Config {
            file: Some(file()),
            events: Some("/var/log/skillpost/events.jsonl".into()),
            settle_ms: Some(250),
            allow_outside: true,
            max_file_size_mb: Some(64),
            forget_after_s: Some(120),
            max_deploys: None,
            template: None,
            lf: false,
            pou: None,
            max_lines: Default::default(),
            on_success: None,
            picture: false,
            simulate: None,
            projects: vec![
                ProjectSpec {
                    path: "/srv/cells/Zelle_A".into(),
                    blackboard: Some("Zelle_A.aml".into()),
                    program: Some("ZELLE_A".into()),
                    ..ProjectSpec::default()
                },
                spec(Path::new("/srv/cells/Zelle_B")),
            ],
            roots: vec![root("/srv/planning/projects")],
        }
    );
    assert_eq!(c.settle(), Duration::from_millis(250));
}

#[test]
fn the_example_in_config_is_valid_and_sets_every_key() {
    let text = include_str!("../../../config/skillpost.toml");
    let c = parse(text, &file()).unwrap();
    assert!(c.events.is_some());
    assert!(c.settle_ms.is_some());
    assert!(!c.projects.is_empty() && !c.roots.is_empty());
    let p = &c.projects[0];
    assert!(p.blackboard.is_some() && p.program.is_some());
    assert!(c.template.is_some());
    assert!(c.roots[0].program.is_some());
    for key in [
        "events",
        "settle_ms",
        "allow_outside",
        "forget_after_s",
        "template",
        "line_endings",
        "max_lines",
        // Commented out: a POU name that an example project lacks would fail it.
        "# pou",
        "[[project]]",
        "[[root]]",
    ] {
        assert!(
            text.contains(&format!("\n{key}")),
            "{key} is set in the example"
        );
    }
    for key in ["path", "blackboard", "program", "template", "line_endings"] {
        assert!(
            text.contains(&format!("\n{key} = ")),
            "{key} is set in the example"
        );
    }
}

#[test]
fn max_lines_sets_the_split_limits_globally_and_per_project() {
    use crate::emit::split::Limits;
    let text = r#"
max_lines = { krl = 3000, urscript = 800 }

[[project]]
path = "/srv/a"
max_lines = { rapid = 0 }

[[project]]
path = "/srv/b"
max_lines = 100

[[root]]
path = "/srv/cells"
"#;
    let c = parse(text, &file()).unwrap();
    let global = Limits {
        krl: Some(3000),
        rapid: None,
        urscript: Some(800),
    };
    assert_eq!(c.max_lines, global);
    // A project's table changes the languages it names.
    assert_eq!(
        c.projects[0].max_lines,
        Limits {
            rapid: Some(0),
            ..global
        }
    );
    assert_eq!(c.projects[1].max_lines, Limits::all(100));
    assert_eq!(c.roots[0].project("/srv/cells/x".into()).max_lines, global);
    for (bad, says) in [
        ("max_lines = -1", "expected a number of lines"),
        ("max_lines = \"many\"", "expected a number of lines"),
        ("max_lines = { cobol = 3 }", "no language"),
    ] {
        let e = err(bad);
        assert!(e.to_string().contains(says), "{bad}: {e}");
    }
}

#[test]
fn empty_file_is_an_empty_config() {
    let c = parse("# nothing\n", &file()).unwrap();
    assert_eq!(
        c,
        Config {
            file: Some(file()),
            ..Config::default()
        }
    );
    assert_eq!(c.settle(), Duration::from_millis(DEFAULT_SETTLE_MS));
}

#[test]
fn relative_paths_resolve_against_the_files_folder() {
    let text = r#"
events = "log/events.jsonl"
[[project]]
path = "cells/./Zelle_A"
[[project]]
path = "../other/Zelle_B"
[[root]]
path = "."
"#;
    let c = parse(text, Path::new("/opt/plan/conf/skillpost.toml")).unwrap();
    assert_eq!(
        c.events.as_deref(),
        Some(Path::new("/opt/plan/conf/log/events.jsonl"))
    );
    assert_eq!(
        c.projects[0].path,
        PathBuf::from("/opt/plan/conf/cells/Zelle_A")
    );
    assert_eq!(c.projects[1].path, PathBuf::from("/opt/plan/other/Zelle_B"));
    assert_eq!(root_paths(&c), vec![PathBuf::from("/opt/plan/conf")]);
}

#[test]
fn load_makes_a_relative_file_path_absolute() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(
        dir.path().join("s.toml"),
        "[[project]]\npath = \"cells/A\"\n",
    )
    .unwrap();
    let c = load(&dir.path().join("s.toml")).unwrap();
    assert_eq!(c.file.as_deref(), Some(dir.path().join("s.toml").as_path()));
    assert_eq!(c.projects[0].path, dir.path().join("cells/A"));

    // A relative file name: against the current directory.
    let cwd = std::env::current_dir().unwrap();
    let c = parse("[[root]]\npath = \"r\"\n", Path::new("conf/s.toml")).unwrap();
    assert_eq!(root_paths(&c), vec![cwd.join("conf/r")]);
    assert_eq!(c.file, Some(cwd.join("conf/s.toml")));
}

#[test]
fn load_of_a_missing_file_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let e = load(&dir.path().join("nope.toml")).unwrap_err();
    assert_eq!(e.file, Some(dir.path().join("nope.toml")));
    assert_eq!(e.line, None);
    assert!(e.message.contains("cannot read"), "{e}");
}

#[test]
fn load_locates_a_template_that_does_not_exist() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("skillpost.toml");
    let text = "settle_ms = 100\n[[project]]\npath = \"p\"\ntemplate = \"missing/krl.toml\"\n";
    std::fs::write(&cfg, text).unwrap();
    let e = load(&cfg).unwrap_err();
    assert_eq!(
        (e.file.as_ref(), e.line, e.column),
        (Some(&cfg), Some(4), Some(12))
    );
    assert!(e.message.contains("missing/krl.toml does not exist"), "{e}");
    // Text alone is not checked against the disk; an existing template loads.
    assert!(parse(text, &cfg).is_ok());
    std::fs::create_dir(dir.path().join("t")).unwrap();
    std::fs::write(dir.path().join("t/krl.toml"), "").unwrap();
    std::fs::write(&cfg, "template = \"t/krl.toml\"\n").unwrap();
    assert!(load(&cfg).is_ok());
}

#[test]
fn unknown_key_at_top_level() {
    let e = err("settle_ms = 100\n  setle = 5\n");
    assert_eq!((e.line, e.column), (Some(2), Some(3)), "{e}");
    assert!(e.message.contains("unknown field `setle`"), "{e}");
    assert_eq!(
        e.to_string(),
        format!("/etc/skillpost/skillpost.toml:2:3: {}", e.message)
    );
}

#[test]
fn unknown_key_inside_project() {
    let e = err("[[project]]\npath = \"a\"\n\n[[project]]\npath = \"b\"\nprogam = \"X\"\n");
    assert_eq!((e.line, e.column), (Some(6), Some(1)), "{e}");
    assert!(e.message.contains("unknown field `progam`"), "{e}");
    assert!(e.message.contains("program"), "lists the known keys: {e}");
}

#[test]
fn unknown_key_column_counts_characters() {
    let e = err("[[root]]\npath = \"Zelle_ä\"; Größe = 1\n");
    // A syntax error after a value: located after the multi-byte characters.
    assert_eq!(e.line, Some(2), "{e}");
    assert_eq!(e.column, Some(17), "{e}");
    let e = err("[[root]]\npath = \"ä\"\n\"größe\" = 1\n");
    assert_eq!((e.line, e.column), (Some(3), Some(1)), "{e}");
    let e = err("[[root]]\npath = \"ä\"\nx = { \"größe\" = 1 }\n");
    assert_eq!(e.line, Some(3), "{e}");
}

#[test]
fn wrong_types() {
    let e = err("settle_ms = \"fast\"\n");
    assert_eq!((e.line, e.column), (Some(1), Some(13)), "{e}");
    assert!(e.message.contains("invalid type"), "{e}");
    assert!(e.message.contains("expected an integer"), "{e}");
    let e = err("allow_outside = \"yes\"\n");
    assert_eq!((e.line, e.column), (Some(1), Some(17)), "{e}");
    let e = err("[[project]]\npath = 3\n");
    assert_eq!((e.line, e.column), (Some(2), Some(8)), "{e}");
    let e = err("project = \"x\"\n");
    assert_eq!(e.line, Some(1), "{e}");
    let e = err("[project]\npath = \"x\"\n");
    assert!(e.message.contains("[[project]]"), "{e}");
    let e = err("[[project]]\nblackboard = \"a.aml\"\n");
    assert!(e.message.contains("missing field `path`"), "{e}");
    assert_eq!(e.line, Some(1), "{e}");
}

#[test]
fn syntax_error_is_located() {
    let e = err("events = \"a\"\nsettle_ms = \n");
    assert_eq!(e.line, Some(2), "{e}");
}

#[test]
fn settle_out_of_range() {
    for (text, col) in [
        ("settle_ms = 0\n", 13),
        ("settle_ms =   60001\n", 15),
        ("settle_ms = -5\n", 13),
    ] {
        let e = err(&format!("# c\n{text}"));
        assert_eq!((e.line, e.column), (Some(2), Some(col)), "{e}");
        assert!(e.message.contains("1..=60000"), "{e}");
    }
    assert_eq!(
        parse("settle_ms = 60000", &file()).unwrap().settle_ms,
        Some(60000)
    );
    assert_eq!(parse("settle_ms = 1", &file()).unwrap().settle_ms, Some(1));
}

#[test]
fn empty_and_home_paths() {
    let e = err("[[project]]\npath = \"a\"\n[[project]]\npath = \"\"\n");
    assert_eq!((e.line, e.column), (Some(4), Some(8)), "{e}");
    assert!(e.message.contains("empty"), "{e}");
    let e = err("[[root]]\npath = \"  \"\n");
    assert_eq!((e.line, e.column), (Some(2), Some(8)), "{e}");
    let e = err("events = \"\"\n");
    assert_eq!((e.line, e.column), (Some(1), Some(10)), "{e}");
    let e = err("[[root]]\npath = \"~/projects\"\n");
    assert_eq!((e.line, e.column), (Some(2), Some(8)), "{e}");
    assert!(e.message.contains("not expanded"), "{e}");
    // A folder merely named `~x` is an ordinary relative path.
    let c = parse("[[root]]\npath = \"~x\"\n", &file()).unwrap();
    assert_eq!(root_paths(&c), vec![PathBuf::from("/etc/skillpost/~x")]);
}

#[test]
fn bad_blackboard() {
    for bb in ["/abs/a.aml", "../a.aml", "./a.aml", "", "~/a.aml"] {
        let e = err(&format!(
            "[[project]]\npath = \"p\"\nblackboard = \"{bb}\"\n"
        ));
        assert_eq!((e.line, e.column), (Some(3), Some(14)), "{bb}: {e}");
    }
    let c = parse(
        "[[project]]\npath = \"p\"\nblackboard = \"sub/B.AML\"\n",
        &file(),
    )
    .unwrap();
    assert_eq!(c.projects[0].blackboard, Some("sub/B.AML".into()));
}

#[test]
fn duplicate_projects_name_both() {
    let e = err(
        "[[project]]\npath = \"cells/A\"\n[[project]]\npath = \"/etc/skillpost/cells/x/../A\"\n",
    );
    assert_eq!((e.line, e.column), (Some(4), Some(8)), "{e}");
    assert!(e.message.contains("\"cells/A\""), "{e}");
    assert!(e.message.contains("/etc/skillpost/cells/x/../A"), "{e}");
    assert!(e.message.contains("line 2, column 8"), "{e}");
    let e = err("[[root]]\npath = \"r\"\n[[root]]\npath = \"./r\"\n");
    assert_eq!((e.line, e.column), (Some(4), Some(8)), "{e}");
    assert!(e.message.contains("[[root]]"), "{e}");
}

#[test]
fn crlf_and_bom() {
    let e = err("\u{feff}events = \"a\"\r\nfoo = 1\r\n");
    assert_eq!((e.line, e.column), (Some(2), Some(1)), "{e}");
    let c = parse("\u{feff}settle_ms = 5\r\n", &file()).unwrap();
    assert_eq!(c.settle_ms, Some(5));
}

#[test]
fn display_without_location() {
    let e = ConfigError {
        file: None,
        line: None,
        column: None,
        message: "boom".into(),
    };
    assert_eq!(e.to_string(), "boom");
    let e = ConfigError {
        file: Some("/x.toml".into()),
        line: None,
        column: None,
        message: "boom".into(),
    };
    assert_eq!(e.to_string(), "/x.toml: boom");
}

#[test]
fn discover_finds_direct_subfolders_with_a_blackboard() {
    let root = tempfile::tempdir().unwrap();
    let r = root.path();
    for d in [
        "b_upper",
        "a_lower",
        "empty",
        "other",
        "nested",
        ".snapshot",
    ] {
        fs::create_dir(r.join(d)).unwrap();
    }
    fs::write(r.join("a_lower/a.aml"), "").unwrap();
    fs::write(r.join("b_upper/A.AML"), "").unwrap();
    fs::write(r.join("other/notes.txt"), "").unwrap();
    fs::write(r.join("other/.#x.aml"), "").unwrap();
    fs::create_dir(r.join("other/x.aml")).unwrap(); // a folder, not a blackboard
    fs::create_dir(r.join("nested/deeper")).unwrap();
    fs::write(r.join("nested/deeper/n.aml"), "").unwrap();
    fs::write(r.join(".snapshot/s.aml"), "").unwrap();
    fs::write(r.join("file.aml"), "").unwrap(); // a file, not a folder
    assert_eq!(discover(r), vec![r.join("a_lower"), r.join("b_upper")]);
    assert!(discover(&r.join("missing")).is_empty());
}

#[cfg(unix)]
#[test]
fn discover_follows_symlinked_folders_and_skips_broken_ones() {
    let root = tempfile::tempdir().unwrap();
    let elsewhere = tempfile::tempdir().unwrap();
    fs::write(elsewhere.path().join("c.aml"), "").unwrap();
    std::os::unix::fs::symlink(elsewhere.path(), root.path().join("linked")).unwrap();
    std::os::unix::fs::symlink("/nonexistent/x", root.path().join("broken")).unwrap();
    assert_eq!(discover(root.path()), vec![root.path().join("linked")]);
}

#[test]
fn resolve_none_one_several_explicit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();

    let e = resolve(&spec(d)).unwrap_err();
    assert!(e.contains("no blackboard"), "{e}");
    assert!(e.contains(&d.display().to_string()), "{e}");

    fs::write(d.join("Zelle_A.aml"), "").unwrap();
    fs::write(d.join("Zelle_A.aml~"), "").unwrap();
    fs::write(d.join(".Zelle_A.aml"), "").unwrap();
    assert_eq!(
        resolve(&spec(d)).unwrap(),
        (d.join("Zelle_A.aml"), "Zelle_A".to_string())
    );

    fs::write(d.join("b.AML"), "").unwrap();
    let e = resolve(&spec(d)).unwrap_err();
    assert!(e.contains("2 blackboards"), "{e}");
    assert!(e.contains("Zelle_A.aml, b.AML"), "{e}");

    let explicit = ProjectSpec {
        path: d.to_path_buf(),
        blackboard: Some("b.AML".into()),
        ..ProjectSpec::default()
    };
    assert_eq!(
        resolve(&explicit).unwrap(),
        (d.join("b.AML"), "b".to_string())
    );
    let both = ProjectSpec {
        program: Some("Not a KRL name!".into()),
        ..explicit
    };
    assert_eq!(
        resolve(&both).unwrap(),
        (d.join("b.AML"), "Not a KRL name!".to_string())
    );

    let e = resolve(&spec(&d.join("missing"))).unwrap_err();
    assert!(e.contains("cannot read"), "{e}");
}

#[test]
fn template_and_line_endings_global_per_project_and_per_root() {
    let text = r#"
template = "krl-team.toml"
line_endings = "lf"
[[project]]
path = "A"
[[project]]
path = "B"
template = "/opt/b.toml"
line_endings = "crlf"
[[root]]
path = "r1"
[[root]]
path = "r2"
line_endings = "CRLF"
template = "t/r2.toml"
"#;
    let c = parse(text, &file()).unwrap();
    assert_eq!(c.template, Some("/etc/skillpost/krl-team.toml".into()));
    assert!(c.lf);
    let a = &c.projects[0];
    assert_eq!(a.template, Some("/etc/skillpost/krl-team.toml".into()));
    assert!(a.lf);
    let b = &c.projects[1];
    assert_eq!(b.template, Some("/opt/b.toml".into()));
    assert!(!b.lf);
    let p1 = c.roots[0].project("/etc/skillpost/r1/X".into());
    assert_eq!(p1.template, Some("/etc/skillpost/krl-team.toml".into()));
    assert!(p1.lf);
    let p2 = c.roots[1].project("/etc/skillpost/r2/Y".into());
    assert_eq!(p2.template, Some("/etc/skillpost/t/r2.toml".into()));
    assert!(!p2.lf);
    assert_eq!(p2.path, PathBuf::from("/etc/skillpost/r2/Y"));

    // The command line's folders get the global settings.
    let m = merge(Some(c), &["/srv/C".into()], None, None);
    let cli = m.projects.last().unwrap();
    assert_eq!(cli.path, PathBuf::from("/srv/C"));
    assert_eq!(cli.template, Some("/etc/skillpost/krl-team.toml".into()));
    assert!(cli.lf);

    // Defaults: built-in template, CRLF, the POU the SFC says.
    let c = parse("[[project]]\npath = \"A\"\n", &file()).unwrap();
    assert_eq!(c.projects[0].template, None);
    assert!(!c.projects[0].lf);
    assert_eq!(c.projects[0].pou, None);

    // `pou` likewise.
    let c = parse(
        "pou = \"Main\"\n[[project]]\npath = \"A\"\n[[project]]\npath = \"B\"\npou = \"Other\"\n\
         [[root]]\npath = \"r\"\n[[root]]\npath = \"s\"\npou = \"S\"\n",
        &file(),
    )
    .unwrap();
    assert_eq!(c.projects[0].pou.as_deref(), Some("Main"));
    assert_eq!(c.projects[1].pou.as_deref(), Some("Other"));
    assert_eq!(c.roots[0].project("x".into()).pou.as_deref(), Some("Main"));
    assert_eq!(c.roots[1].project("x".into()).pou.as_deref(), Some("S"));
}

#[test]
fn bad_line_endings_and_templates_are_located() {
    let e = err("\nline_endings = \"unix\"\n");
    assert_eq!((e.line, e.column), (Some(2), Some(16)), "{e}");
    assert!(
        e.message.contains("\"crlf\"") && e.message.contains("\"lf\""),
        "{e}"
    );
    let e = err("[[root]]\npath = \"r\"\nline_endings = \"cr\"\n");
    assert_eq!((e.line, e.column), (Some(3), Some(16)), "{e}");
    let e = err("[[project]]\npath = \"p\"\ntemplate = \"\"\n");
    assert_eq!((e.line, e.column), (Some(3), Some(12)), "{e}");
    let e = err("template = \"~/t.toml\"\n");
    assert!(e.message.contains("not expanded"), "{e}");
    let e = err("[[root]]\npath = \"r\"\ntemplat = \"t\"\n");
    assert!(e.message.contains("unknown field `templat`"), "{e}");
}

#[test]
fn program_patterns() {
    let c = parse(
        "[[root]]\npath = \"r\"\nprogram = \"P_{folder}\"\n[[root]]\npath = \"s\"\n",
        &file(),
    )
    .unwrap();
    assert_eq!(c.roots[0].program.as_deref(), Some("P_{folder}"));
    assert_eq!(c.roots[1].program, None);
    for (text, col) in [
        ("program = \"Zelle A\"", 11),
        ("program = \"{ordner}\"", 11),
        ("program = \"P_{folder\"", 11),
        ("program = \"1abc\"", 11),
    ] {
        let e = err(&format!("[[root]]\npath = \"r\"\n{text}\n"));
        assert_eq!((e.line, e.column), (Some(3), Some(col)), "{text}: {e}");
    }
    let e = err("[[project]]\npath = \"p\"\nprogram = \"Zelle A\"\n");
    assert!(e.message.contains("not a KRL name"), "{e}");
    assert!(e.message.contains("\"Zelle_A\""), "says how to fix it: {e}");
    let e = err("[[root]]\npath = \"r\"\nprogram = \"{ordner}\"\n");
    assert!(e.message.contains("{folder}"), "{e}");
    let e = err("[[root]]\npath = \"r\"\nprogram = \"Loop\"\n");
    assert!(
        e.message.contains("keyword") && e.message.contains("\"Loop_\""),
        "{e}"
    );

    let bb = Path::new("/r/Palletizing Cell/Palletizing Cell.aml");
    let folder = Path::new("/r/Palletizing Cell");
    assert_eq!(
        program_name(None, folder, bb),
        ProgramName {
            name: "Palletizing_Cell".into(),
            derived_from: Some("Palletizing Cell".into()),
        }
    );
    let ok = Path::new("/r/x/Zelle_A.aml");
    assert_eq!(
        program_name(None, Path::new("/r/x"), ok),
        ProgramName {
            name: "Zelle_A".into(),
            derived_from: None,
        }
    );
    let p = program_name(Some("{folder}"), Path::new("/r/Zelle_Übergabe"), ok);
    assert_eq!(p.name, "Zelle_Uebergabe");
    assert_eq!(p.derived_from.as_deref(), Some("Zelle_Übergabe"));
    let p = program_name(Some("Cell_{folder}_{blackboard}"), Path::new("/r/7"), ok);
    assert_eq!(p.name, "Cell_7_Zelle_A");
    assert_eq!(p.derived_from, None);
    let p = program_name(Some("Main"), folder, bb);
    assert_eq!(p.name, "Main");
    let p = program_name(Some("{folder}"), Path::new("/r/2024 Linie"), ok);
    assert_eq!(p.name, "_2024_Linie");
}

#[test]
fn forget_after_out_of_range_is_located() {
    let e = parse("\nforget_after_s = 0\n", &file()).unwrap_err();
    assert_eq!((e.line, e.column), (Some(2), Some(18)));
    assert!(e.message.contains("forget_after_s"), "{e}");
    let c = parse("forget_after_s = 5\n", &file()).unwrap();
    assert_eq!(c.forget_after(), Duration::from_secs(5));
    assert_eq!(
        Config::default().forget_after(),
        Duration::from_secs(DEFAULT_FORGET_AFTER_S)
    );
}

#[test]
fn a_fifo_or_device_as_the_configuration_is_refused_at_once() {
    let d = tempfile::tempdir().unwrap();
    let fifo = d.path().join("skillpost.toml");
    rustix::fs::mknodat(
        rustix::fs::CWD,
        &fifo,
        rustix::fs::FileType::Fifo,
        rustix::fs::Mode::from_raw_mode(0o600),
        0,
    )
    .unwrap();
    let t = std::time::Instant::now();
    let e = load(&fifo).unwrap_err();
    assert!(e.message.contains("not a regular file"), "{e}");
    let link = d.path().join("zero.toml");
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    assert!(
        load(&link)
            .unwrap_err()
            .message
            .contains("not a regular file")
    );
    let big = d.path().join("big.toml");
    std::fs::write(&big, vec![b'#'; MAX_CONFIG_SIZE as usize + 1]).unwrap();
    assert!(load(&big).unwrap_err().message.contains("limit"));
    assert!(t.elapsed() < Duration::from_secs(1));
}

#[test]
fn max_file_size_out_of_range_is_located() {
    let e = parse("\nmax_file_size_mb = 0\n", &file()).unwrap_err();
    assert_eq!((e.line, e.column), (Some(2), Some(20)), "{e}");
    assert!(e.message.contains("1..=4096"), "{e}");
}

#[test]
fn deploy_hooks_are_inherited_overridden_and_checked_where_written() {
    let c = parse(
        "on_success = [\"deploy\", \"{src}\"]\ndeploy_timeout_s = 30\n\
         [[project]]\npath = \"/srv/A\"\n\
         [[project]]\npath = \"/srv/B\"\non_success = [\"bin/copy\", \"{outputs}\"]\n\
         [[project]]\npath = \"/srv/C\"\ndeploy_timeout_s = 5\n\
         [[root]]\npath = \"/srv/R\"\n",
        &file(),
    )
    .unwrap();
    let hook = |i: usize| c.projects[i].on_success.clone().unwrap();
    assert_eq!(hook(0).argv, ["deploy", "{src}"]);
    assert_eq!(hook(0).timeout, Duration::from_secs(30));
    // A relative program path is the configuration folder's.
    assert_eq!(hook(1).argv, ["/etc/skillpost/bin/copy", "{outputs}"]);
    assert_eq!(hook(2).argv, ["deploy", "{src}"]);
    assert_eq!(hook(2).timeout, Duration::from_secs(5));
    assert_eq!(c.roots[0].on_success, c.on_success);
    assert_eq!(
        c.roots[0].project("/srv/R/x".into()).on_success,
        c.on_success
    );
    // Without any: none, and the default timeout for a hook without one.
    let c = parse("on_success = [\"true\"]\n", &file()).unwrap();
    assert_eq!(c.on_success.unwrap().timeout, Duration::from_secs(60));
    for (text, at, says) in [
        ("on_success = []\n", (1, 14), "empty"),
        (
            "on_success = [\"cp\", \"{sauce}\"]\n",
            (1, 14),
            "unknown placeholder",
        ),
        ("deploy_timeout_s = 0\n", (1, 20), "1..=3600"),
        (
            "[[project]]\npath = \"/a\"\non_success = [\"cp\", \"x{outputs}\"]\n",
            (3, 14),
            "whole argument",
        ),
        (
            "on_success = \"deploy {src}\"\n",
            (1, 14),
            "list of strings",
        ),
    ] {
        let e = err(text);
        assert_eq!((e.line, e.column), (Some(at.0), Some(at.1)), "{text}: {e}");
        assert!(e.message.contains(says), "{text}: {e}");
    }
}

#[test]
fn merge_precedence() {
    let cwd = std::env::current_dir().unwrap();
    let file = Config {
        file: Some("/etc/s.toml".into()),
        events: Some("/var/log/e.jsonl".into()),
        settle_ms: Some(300),
        allow_outside: true,
        max_file_size_mb: None,
        forget_after_s: None,
        max_deploys: None,
        template: None,
        lf: false,
        pou: None,
        max_lines: Default::default(),
        on_success: None,
        picture: false,
        simulate: None,
        projects: vec![ProjectSpec {
            path: "/srv/A".into(),
            blackboard: Some("A.aml".into()),
            program: Some("PA".into()),
            ..ProjectSpec::default()
        }],
        roots: vec![root("/srv/root")],
    };

    // Nothing on the command line: the file as is.
    assert_eq!(merge(Some(file.clone()), &[], None, None), file);

    let m = merge(
        Some(file.clone()),
        &["/srv/A".into(), "rel/B".into(), "/srv/C/".into()],
        Some("ev.jsonl".into()),
        Some(50),
    );
    assert_eq!(m.events, Some(cwd.join("ev.jsonl")));
    assert_eq!(m.settle_ms, Some(50));
    assert!(m.allow_outside);
    assert_eq!(m.roots, file.roots);
    assert_eq!(m.file, file.file);
    assert_eq!(
        m.projects,
        vec![
            file.projects[0].clone(),
            spec(&cwd.join("rel/B")),
            spec(Path::new("/srv/C")),
        ]
    );

    // No file: only the command line.
    let m = merge(None, &["x".into()], None, None);
    assert_eq!(
        m,
        Config {
            projects: vec![spec(&cwd.join("x"))],
            ..Config::default()
        }
    );
}

#[test]
fn settle_is_capped() {
    let c = Config {
        settle_ms: Some(10_000_000),
        ..Config::default()
    };
    assert_eq!(c.settle(), Duration::from_millis(60_000));
    let c = Config {
        settle_ms: Some(0),
        ..Config::default()
    };
    assert_eq!(c.settle(), Duration::from_millis(1));
}

#[test]
fn blackboard_names() {
    assert!(is_blackboard_name(OsStr::new("a.aml")));
    assert!(is_blackboard_name(OsStr::new("A.AmL")));
    assert!(!is_blackboard_name(OsStr::new(".aml")));
    assert!(!is_blackboard_name(OsStr::new(".#a.aml")));
    assert!(!is_blackboard_name(OsStr::new("a.aml~")));
    assert!(!is_blackboard_name(OsStr::new("a.aml.swp")));
    assert!(!is_blackboard_name(OsStr::new("ä.xml")));
    assert!(is_blackboard_name(OsStr::new("Zelle_ä.aml")));
}

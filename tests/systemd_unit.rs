//! The systemd unit in `systemd/skillpost.service`: hardened, and accepted by
//! `systemd-analyze verify` (when systemd's analyzer is installed).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

const UNIT: &str = include_str!("../systemd/skillpost.service");
const INSTALLED_BINARY: &str = "/usr/local/bin/skillpost";

/// The `Key=value` lines of the unit (comments and section headers left out).
fn directives(unit: &str) -> Vec<(&str, &str)> {
    unit.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with(';'))
        .filter(|l| !l.starts_with('['))
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| (k.trim(), v.trim()))
        .collect()
}

fn value<'a>(unit: &'a str, key: &str) -> Vec<&'a str> {
    directives(unit)
        .into_iter()
        .filter(|(k, _)| *k == key)
        .map(|(_, v)| v)
        .collect()
}

#[test]
fn unit_has_the_key_lines() {
    for (key, expected) in [
        ("Type", "notify"),
        ("NotifyAccess", "main"),
        ("NoNewPrivileges", "yes"),
        ("ProtectSystem", "strict"),
        ("ProtectHome", "yes"),
        ("PrivateTmp", "yes"),
        ("PrivateDevices", "yes"),
        ("RestrictAddressFamilies", "AF_UNIX"),
        ("SystemCallFilter", "@system-service"),
        // The write-back's lease on planners' blackboards; nothing else.
        ("CapabilityBoundingSet", "CAP_LEASE"),
        ("AmbientCapabilities", "CAP_LEASE"),
        ("ExecReload", "/bin/kill -HUP $MAINPID"),
        ("Restart", "on-failure"),
        ("User", "skillpost"),
        ("Group", "skillpost"),
    ] {
        assert!(
            value(UNIT, key).contains(&expected),
            "the unit should have `{key}={expected}`, has {:?}",
            value(UNIT, key)
        );
    }
    assert!(
        !value(UNIT, "WatchdogSec").is_empty(),
        "WatchdogSec= missing"
    );
    assert!(
        !value(UNIT, "ReadWritePaths").is_empty(),
        "ReadWritePaths= missing"
    );
    let exec = value(UNIT, "ExecStart");
    assert_eq!(exec.len(), 1, "one ExecStart=: {exec:?}");
    assert!(
        exec[0].starts_with(&format!("{INSTALLED_BINARY} watch --config ")),
        "ExecStart= runs the daemon with a configuration file: {}",
        exec[0]
    );
    assert_eq!(value(UNIT, "WantedBy"), ["multi-user.target"]);
}

/// A copy of the unit, named `skillpost.service` in a temporary folder, with `ExecStart=`
/// running `binary` instead of the installed path.
fn unit_copy(dir: &Path, binary: &Path, extra: &str) -> PathBuf {
    let binary = binary.to_str().expect("a UTF-8 binary path");
    let binary = if binary.contains(char::is_whitespace) {
        format!("\"{binary}\"")
    } else {
        binary.to_string()
    };
    let from = format!("ExecStart={INSTALLED_BINARY} ");
    assert!(UNIT.contains(&from), "ExecStart= not found in the unit");
    let mut text = UNIT.replace(&from, &format!("ExecStart={binary} "));
    if !extra.is_empty() {
        text = text.replace("[Service]\n", &format!("[Service]\n{extra}\n"));
    }
    let path = dir.join("skillpost.service");
    std::fs::write(&path, text).unwrap();
    path
}

/// Runs `systemd-analyze verify` on `unit`: `None` when the analyzer is not installed, else the
/// exit success and the output lines about this unit.
fn verify(unit: &Path) -> Option<(bool, Vec<String>, String)> {
    let output = match Command::new("systemd-analyze")
        .arg("verify")
        .arg(unit)
        .env("SYSTEMD_LOG_COLOR", "0")
        .output()
    {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
        Err(e) => panic!("cannot run systemd-analyze: {e}"),
    };
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let dir = unit.parent().unwrap().to_str().unwrap();
    let ours = all
        .lines()
        .filter(|l| l.contains(dir) || l.contains("skillpost.service"))
        .map(str::to_string)
        .collect();
    Some((output.status.success(), ours, all))
}

#[test]
fn systemd_analyze_verify_accepts_the_unit() {
    let dir = tempfile::tempdir().unwrap();
    let unit = unit_copy(dir.path(), Path::new(env!("CARGO_BIN_EXE_skillpost")), "");
    let Some((ok, ours, all)) = verify(&unit) else {
        common::skip(
            "`systemd-analyze` is not installed, so systemd/skillpost.service was not \
             verified (install systemd, e.g. `apt-get install systemd`, to run this check)",
        );
        return;
    };
    assert!(ok, "systemd-analyze verify failed:\n{all}");
    assert!(
        ours.is_empty(),
        "systemd-analyze verify complains about the unit:\n{}",
        ours.join("\n")
    );
}

/// The check above would notice a mistake: an unknown directive and an invalid value are
/// reported (systemd-analyze exits 0 for them, so the output is what counts).
#[test]
fn systemd_analyze_verify_catches_mistakes() {
    let dir = tempfile::tempdir().unwrap();
    let unit = unit_copy(
        dir.path(),
        Path::new(env!("CARGO_BIN_EXE_skillpost")),
        "ProtectSytem=strict\nRestrictRealtime=maybe",
    );
    let Some((_, ours, all)) = verify(&unit) else {
        common::skip("`systemd-analyze` is not installed");
        return;
    };
    assert!(
        ours.iter().any(|l| l.contains("ProtectSytem")),
        "the unknown key is reported:\n{all}"
    );
    assert!(
        ours.iter().any(|l| l.contains("maybe")),
        "the invalid value is reported:\n{all}"
    );
}

use super::*;
use lease::leases_work;
use std::io::Write as _;
use std::time::Duration;

/// The end of the original sample blackboard (lines 1-2 and 95-106).
const SAMPLE: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<CAEXFile FileName="Blackboard.aml" SchemaVersion="2.15">
  <InstanceHierarchy Name="Blackboard">
    <InternalElement Name="Code" ID="{00000000-0000-0000-0000-000000000018}">
      <ExternalInterface Name="KRL code" ID="{00000000-0000-0000-0000-000000000019}">
        <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>none</Value></Attribute>
      </ExternalInterface>
    </InternalElement>
  </InstanceHierarchy>
</CAEXFile>
"#;

/// The site of the refURI attribute, as the reader finds it.
fn site(text: &str) -> SpliceSite {
    let d = roxmltree::Document::parse(text).unwrap();
    let a = d
        .descendants()
        .find(|n| n.tag_name().name() == "Attribute")
        .unwrap();
    SpliceSite::of(a).unwrap()
}

fn written(text: &str) -> String {
    text.replace(">none<", ">x.src<")
}

/// A folder with `Blackboard.aml` holding `SAMPLE`.
fn project() -> (tempfile::TempDir, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("Blackboard.aml");
    fs::write(&p, SAMPLE).unwrap();
    (d, p)
}

fn run(p: &Path, opts: Opts, hook: &mut dyn FnMut(Point)) -> WriteBackOutcome {
    write_back_with(
        p,
        SAMPLE.as_bytes(),
        false,
        &[(&site(SAMPLE), "x.src")],
        &opts,
        hook,
    )
    .unwrap()
}

use crate::write::temp_leftovers;

/// A rename save: a new file renamed over the name.
fn rename_save(p: &Path, text: &str) {
    let tmp = p.with_file_name(format!("save-{}.tmp", std::process::id()));
    fs::write(&tmp, text).unwrap();
    fs::rename(&tmp, p).unwrap();
}

/// Waits until `/proc/locks` lists a lease on inode `ino` that is being broken (a process
/// blocked in `open` by it).
fn lease_breaking(ino: u64, timeout: Duration) -> bool {
    let end = std::time::Instant::now() + timeout;
    let suffix = format!(":{ino}");
    while std::time::Instant::now() < end {
        let locks = fs::read_to_string("/proc/locks").unwrap_or_default();
        if locks.lines().any(|l| {
            l.contains("LEASE")
                && l.contains("BREAK")
                && l.split_whitespace().any(|w| w.ends_with(&suffix))
        }) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    false
}

#[test]
fn writes_only_the_value_and_keeps_bom_mode_and_link() {
    let (d, p) = project();
    let mut bytes = BOM.to_vec();
    bytes.extend_from_slice(SAMPLE.replace('\n', "\r\n").as_bytes());
    fs::write(&p, &bytes).unwrap();
    fs::set_permissions(&p, std::os::unix::fs::PermissionsExt::from_mode(0o640)).unwrap();
    let link = d.path().join("Link.aml");
    std::os::unix::fs::symlink("Blackboard.aml", &link).unwrap();
    let text = std::str::from_utf8(&bytes[3..]).unwrap();
    let out = write_back(&link, &bytes, true, &site(text), "x.src").unwrap();
    assert_eq!(out, WriteBackOutcome::Written);
    let mut want = BOM.to_vec();
    want.extend_from_slice(written(text).as_bytes());
    assert_eq!(fs::read(&p).unwrap(), want);
    assert!(
        fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(fs::metadata(&p).unwrap().mode() & 0o7777, 0o640);
    assert!(temp_leftovers(d.path()).is_empty());
    // Again: already right, nothing touched.
    let text2 = std::str::from_utf8(&want[3..]).unwrap();
    let before = fs::metadata(&p).unwrap().modified().unwrap();
    assert_eq!(
        write_back(&p, &want, true, &site(text2), "x.src").unwrap(),
        WriteBackOutcome::AlreadyRight
    );
    assert_eq!(fs::metadata(&p).unwrap().modified().unwrap(), before);
}

#[test]
fn changed_or_deleted_after_reading_is_skipped() {
    let (d, p) = project();
    let edited = SAMPLE.replace("Blackboard\"", "Blackboard2\"");
    fs::write(&p, &edited).unwrap();
    assert_eq!(
        run(&p, Opts::default(), &mut |_| {}),
        WriteBackOutcome::SkippedChangedOnDisk
    );
    assert_eq!(fs::read_to_string(&p).unwrap(), edited);
    fs::remove_file(&p).unwrap();
    assert_eq!(
        run(&p, Opts::default(), &mut |_| {}),
        WriteBackOutcome::SkippedChangedOnDisk
    );
    assert!(!p.exists());
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn a_fifo_swapped_in_before_the_open_is_skipped_at_once() {
    // The blackboard was a regular file when checked; a FIFO replaces it before it is
    // opened. Opening it must not wait for a writer (the compile would hang for ever).
    let (d, p) = project();
    let (tx, rx) = std::sync::mpsc::channel();
    let path = p.clone();
    std::thread::spawn(move || {
        let out = run(&path, Opts::default(), &mut |pt| {
            if matches!(pt, Point::Staged) {
                fs::remove_file(&path).unwrap();
                let st = std::process::Command::new("mkfifo")
                    .arg(&path)
                    .status()
                    .unwrap();
                assert!(st.success());
            }
        });
        let _ = tx.send(out);
    });
    let out = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("the write-back waited on a FIFO");
    assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
    use std::os::unix::fs::FileTypeExt as _;
    assert!(fs::symlink_metadata(&p).unwrap().file_type().is_fifo());
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn caller_bugs_are_errors() {
    let (_d, p) = project();
    let e = write_back(&p, SAMPLE.as_bytes(), true, &site(SAMPLE), "x").unwrap_err();
    assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
    let bad = SpliceSite {
        replace: 0..SAMPLE.len() + 1,
        ..SpliceSite::default()
    };
    let e = write_back(&p, SAMPLE.as_bytes(), false, &bad, "x").unwrap_err();
    assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
    assert_eq!(fs::read_to_string(&p).unwrap(), SAMPLE);
}

/// Every combination of lease and exchange that the machine offers.
fn modes(dir: &Path) -> Vec<Opts> {
    let mut v = vec![Opts {
        lease: false,
        exchange: true,
    }];
    if leases_work(dir) {
        v.push(Opts::default());
    }
    v
}

#[test]
fn rename_save_before_the_exchange_survives() {
    let (d, p) = project();
    for opts in modes(d.path()).into_iter().chain([Opts {
        lease: true,
        exchange: false,
    }]) {
        fs::write(&p, SAMPLE).unwrap();
        let save = SAMPLE.replace("<InstanceHierarchy", "<!-- save 1 --><InstanceHierarchy");
        let out = run(&p, opts, &mut |pt| {
            if pt == Point::BeforeExchange {
                rename_save(&p, &save);
            }
        });
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk, "{opts:?}");
        assert_eq!(fs::read_to_string(&p).unwrap(), save, "{opts:?}");
        assert!(temp_leftovers(d.path()).is_empty());
    }
}

#[test]
fn rename_save_right_after_the_exchange_stays() {
    let (d, p) = project();
    for opts in modes(d.path()) {
        fs::write(&p, SAMPLE).unwrap();
        let save = SAMPLE.replace("<InstanceHierarchy", "<!-- save 2 --><InstanceHierarchy");
        let out = run(&p, opts, &mut |pt| {
            if let Point::AfterExchange(_) = pt {
                rename_save(&p, &save);
            }
        });
        // Our write happened, and the newer save replaced it, as saves do.
        assert_eq!(out, WriteBackOutcome::Written, "{opts:?}");
        assert_eq!(fs::read_to_string(&p).unwrap(), save, "{opts:?}");
        assert!(temp_leftovers(d.path()).is_empty());
    }
}

#[test]
fn saves_during_the_swap_back_end_with_the_newest() {
    // With a lease on our file the save the exchange took is taken over in place (below)
    // unless another program holds it open: `held` keeps it open (a reader) for the whole
    // wait, so the swap back runs.
    let (d, p) = project();
    for opts in modes(d.path()) {
        fs::write(&p, SAMPLE).unwrap();
        let mut n = 0;
        let mut held = None;
        let out = run(&p, opts, &mut |pt| match pt {
            Point::BeforeExchange => {
                rename_save(&p, "save A");
                held = Some(fs::File::open(&p).unwrap());
            }
            Point::SwapBack(_) if n < 3 => {
                n += 1;
                rename_save(&p, &format!("save B{n}"));
            }
            _ => {}
        });
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
        assert_eq!(fs::read_to_string(&p).unwrap(), "save B3", "{opts:?}");
        assert!(temp_leftovers(d.path()).is_empty());
        drop(held);
    }
}

#[test]
fn a_save_while_the_taken_save_is_copied_stays() {
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let out = run(&p, Opts::default(), &mut |pt| match pt {
        Point::BeforeExchange => rename_save(&p, "save A"),
        Point::Adopt => rename_save(&p, "save B"),
        _ => {}
    });
    assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
    assert_eq!(fs::read_to_string(&p).unwrap(), "save B");
    assert!(temp_leftovers(d.path()).is_empty());
}

/// Our lease goes with our descriptor, also while a copy of the open file lives on: a hook
/// being started holds one of every descriptor until its `exec`. Then our own next open of
/// the blackboard (without blocking, as the hash check opens it) was refused as long as the
/// copy lived, and taken for a change: a second, forced compile (seen in CI: 601 of 600).
#[test]
fn our_lease_goes_with_our_descriptor_while_a_copy_lives_on() {
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let f = lease::Unleased(fs::File::open(&p).unwrap());
    assert!(matches!(lease::take(&f), Ok(true)));
    // What a hook being started holds: the same open file.
    let copy = f.try_clone().unwrap();
    drop(f);
    // The daemon's hash check (after a write-back, and before a compile).
    let hashed = crate::load::hash_file(&p, 1 << 20);
    assert!(hashed.is_ok(), "refused: {:?}", hashed.err());
    drop(copy);
}

/// A writer in another thread: opens `p` for writing (without truncating) when started,
/// says so, and writes `text` over the whole file through that descriptor when told.
fn descriptor_writer(
    p: &Path,
    text: &'static str,
) -> (
    std::sync::mpsc::Receiver<()>,
    std::sync::mpsc::Sender<()>,
    std::thread::JoinHandle<()>,
) {
    let (opened_tx, opened) = std::sync::mpsc::channel();
    let (go, go_rx) = std::sync::mpsc::channel::<()>();
    let p = p.to_owned();
    let t = std::thread::spawn(move || {
        let mut f = fs::File::options().read(true).write(true).open(&p).unwrap();
        opened_tx.send(()).unwrap();
        go_rx.recv().unwrap();
        f.set_len(0).unwrap();
        f.write_all(text.as_bytes()).unwrap();
    });
    (opened, go, t)
}

#[test]
fn a_save_through_a_descriptor_opened_after_the_exchange_ends_at_the_name() {
    // Issue 24, finding 1: the planner saves by rename (before our exchange, so the
    // exchange takes the save), opens the name at once and writes through that descriptor a
    // moment later. Its `open` lands while our new file stands at the name; the write must
    // end up at the name, not in a file the write-back then removes.
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let mut writer = None;
    let out = run(&p, Opts::default(), &mut |pt| match pt {
        Point::BeforeExchange => rename_save(&p, "save 1"),
        Point::AfterExchange(_) => {
            let ino = fs::metadata(&p).unwrap().ino();
            let w = descriptor_writer(&p, "save 2 through the descriptor");
            // Its open is blocked by the lease on our file (now at the name).
            assert!(lease_breaking(ino, Duration::from_secs(10)));
            writer = Some(w);
        }
        _ => {}
    });
    assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
    let (opened, go, t) = writer.unwrap();
    opened.recv_timeout(Duration::from_secs(10)).unwrap();
    // Meanwhile the name holds the save the exchange took.
    assert_eq!(fs::read_to_string(&p).unwrap(), "save 1");
    go.send(()).unwrap();
    t.join().unwrap();
    assert_eq!(
        fs::read_to_string(&p).unwrap(),
        "save 2 through the descriptor"
    );
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn a_save_through_a_descriptor_opened_before_the_exchange_ends_at_the_name() {
    // The same planner, faster: its open lands before the exchange and gets its rename
    // save, which the exchange then takes away. Taking it over waits until the writer is
    // done with it, so its write is in what goes back to the name.
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let mut writer = None;
    let out = run(&p, Opts::default(), &mut |pt| {
        if pt == Point::BeforeExchange {
            rename_save(&p, "save 1");
            let w = descriptor_writer(&p, "save 2 through the descriptor");
            w.0.recv_timeout(Duration::from_secs(10)).unwrap();
            w.1.send(()).unwrap();
            writer = Some(w.2);
        }
    });
    writer.unwrap().join().unwrap();
    assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
    assert_eq!(
        fs::read_to_string(&p).unwrap(),
        "save 2 through the descriptor"
    );
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn a_reader_of_the_old_file_after_the_exchange_leaves_the_write_back_standing() {
    // A reader that looked the name up before the exchange opens the old file (blocked by
    // our lease), reads it and closes it: nothing changed, so the new file stays.
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let mut reader = None;
    let out = run(&p, Opts::default(), &mut |pt| {
        if let Point::AfterExchange(old) = pt {
            let ino = fs::metadata(old).unwrap().ino();
            let old = old.to_owned();
            reader = Some(std::thread::spawn(move || {
                fs::read_to_string(&old).unwrap()
            }));
            assert!(lease_breaking(ino, Duration::from_secs(10)));
        }
    });
    assert_eq!(reader.unwrap().join().unwrap(), SAMPLE);
    assert_eq!(out, WriteBackOutcome::Written);
    assert_eq!(fs::read_to_string(&p).unwrap(), written(SAMPLE));
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn a_double_race_keeps_both_files() {
    // The exchange takes a save that another program keeps open (for the whole wait), and a
    // writer opens the name while our file stands there: only one can have the name. The
    // save goes back; ours is kept beside it, with what the writer writes, and the
    // write-back is an error naming it: nothing is lost silently.
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let mut reader = None;
    let mut writer = None;
    let r = write_back_with(
        &p,
        SAMPLE.as_bytes(),
        false,
        &[(&site(SAMPLE), "x.src")],
        &Opts::default(),
        &mut |pt| match pt {
            Point::BeforeExchange => {
                rename_save(&p, "save 1");
                reader = Some(fs::File::open(&p).unwrap());
            }
            Point::AfterExchange(_) => {
                let ino = fs::metadata(&p).unwrap().ino();
                let w = descriptor_writer(&p, "through the descriptor");
                assert!(lease_breaking(ino, Duration::from_secs(10)));
                writer = Some(w);
            }
            _ => {}
        },
    );
    let e = r.unwrap_err().to_string();
    let kept = d.path().join("Blackboard.aml.skillpost-kept-1");
    assert!(e.contains(&kept.display().to_string()), "{e}");
    let (opened, go, t) = writer.unwrap();
    opened.recv_timeout(Duration::from_secs(10)).unwrap();
    go.send(()).unwrap();
    t.join().unwrap();
    drop(reader);
    assert_eq!(fs::read_to_string(&p).unwrap(), "save 1");
    assert_eq!(fs::read_to_string(&kept).unwrap(), "through the descriptor");
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn a_read_only_blackboard_is_not_replaced() {
    let (d, p) = project();
    fs::set_permissions(&p, std::os::unix::fs::PermissionsExt::from_mode(0o444)).unwrap();
    let ino = fs::metadata(&p).unwrap().ino();
    for opts in modes(d.path()) {
        assert_eq!(
            run(&p, opts, &mut |_| {}),
            WriteBackOutcome::SkippedReadOnly
        );
    }
    assert_eq!(fs::read_to_string(&p).unwrap(), SAMPLE);
    assert_eq!(fs::metadata(&p).unwrap().ino(), ino);
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn writer_into_the_old_file_after_the_exchange_is_put_back() {
    // A writer that resolved the name before the exchange writes into the old inode, which
    // the exchange moved to the temporary name: it must end up at the name.
    let (d, p) = project();
    for opts in modes(d.path()) {
        fs::write(&p, SAMPLE).unwrap();
        let mut writer = None;
        let out = run(&p, opts, &mut |pt| {
            if let Point::AfterExchange(old) = pt {
                let ino = fs::metadata(old).unwrap().ino();
                let old = old.to_owned();
                // Another thread: with a lease, its `open` blocks until the lease goes.
                let w = std::thread::spawn(move || {
                    let mut f = fs::File::options()
                        .write(true)
                        .truncate(true)
                        .open(&old)
                        .unwrap();
                    f.write_all(b"in place").unwrap();
                });
                if opts.lease {
                    // Go on once the writer is blocked in `open` (not after a guessed sleep).
                    assert!(lease_breaking(ino, Duration::from_secs(10)), "{opts:?}");
                    writer = Some(w);
                } else {
                    // Nothing blocks it: its write has happened before the checks go on.
                    w.join().unwrap();
                }
            }
        });
        if let Some(w) = writer {
            w.join().unwrap();
        }
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk, "{opts:?}");
        assert_eq!(fs::read_to_string(&p).unwrap(), "in place", "{opts:?}");
        assert!(temp_leftovers(d.path()).is_empty());
    }
}

#[test]
fn writer_that_opened_before_is_waited_for() {
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    // Opened before the write-back (an editor about to write): the lease is refused.
    let mut f = fs::File::options().write(true).open(&p).unwrap();
    assert_eq!(
        run(&p, Opts::default(), &mut |_| {}),
        WriteBackOutcome::SkippedInUse
    );
    f.set_len(0).unwrap();
    f.write_all(b"editor").unwrap();
    drop(f);
    assert_eq!(fs::read_to_string(&p).unwrap(), "editor");
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn writer_opening_during_the_lease_is_blocked_then_wins() {
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let mut writer = None;
    let out = run(&p, Opts::default(), &mut |pt| {
        if pt == Point::Read {
            let ino = fs::metadata(&p).unwrap().ino();
            let p = p.clone();
            writer = Some(std::thread::spawn(move || {
                let mut f = fs::File::options()
                    .write(true)
                    .truncate(true)
                    .open(&p)
                    .unwrap();
                f.write_all(b"in place").unwrap();
            }));
            // Go on only once the writer is blocked in `open` by our lease (a sleep is not
            // enough on a loaded machine): the kernel lists the lease as breaking.
            assert!(
                lease_breaking(ino, Duration::from_secs(10)),
                "the writer's open did not break the lease"
            );
        }
    });
    writer.unwrap().join().unwrap();
    assert_eq!(out, WriteBackOutcome::SkippedInUse);
    assert_eq!(fs::read_to_string(&p).unwrap(), "in place");
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn hard_linked_blackboard_is_not_split() {
    let (d, p) = project();
    let other = d.path().join("Other.aml");
    fs::hard_link(&p, &other).unwrap();
    for opts in modes(d.path()) {
        assert_eq!(
            run(&p, opts, &mut |_| {}),
            WriteBackOutcome::SkippedHardLinked
        );
    }
    assert_eq!(fs::read_to_string(&p).unwrap(), SAMPLE);
    assert_eq!(
        fs::metadata(&p).unwrap().ino(),
        fs::metadata(&other).unwrap().ino()
    );
    assert!(temp_leftovers(d.path()).is_empty());
}

#[test]
fn fallbacks_write_when_nothing_races() {
    let (d, p) = project();
    for opts in [
        Opts {
            lease: false,
            exchange: false,
        },
        Opts {
            lease: false,
            exchange: true,
        },
        Opts {
            lease: true,
            exchange: false,
        },
        Opts::default(),
    ] {
        fs::write(&p, SAMPLE).unwrap();
        assert_eq!(run(&p, opts, &mut |_| {}), WriteBackOutcome::Written);
        assert_eq!(fs::read_to_string(&p).unwrap(), written(SAMPLE));
        assert!(temp_leftovers(d.path()).is_empty());
    }
}

#[test]
fn a_lease_break_does_not_kill_the_process() {
    // Another process opens the leased file: the kernel sends SIGIO, whose default action
    // would end this test process. The handler makes it harmless; the break shows in
    // F_GETLEASE, and the opener goes on once the lease is released.
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let f = lease::Unleased(fs::File::open(&p).unwrap());
    assert!(lease::take(&f).unwrap());
    let cat = std::process::Command::new("cat")
        .arg(&p)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while lease::intact(&f) {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no lease break seen"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(50));
    drop(f);
    let out = cat.wait_with_output().unwrap();
    assert!(out.status.success());
    assert_eq!(out.stdout, SAMPLE.as_bytes());
}

/// The window that remains with a lease and the exchange: from the exchange to the end of
/// the checks (`cargo test --release --lib window -- --ignored --nocapture`).
#[test]
#[ignore]
fn window() {
    let (d, p) = project();
    if !leases_work(d.path()) {
        return;
    }
    let mut times = Vec::new();
    for _ in 0..2000 {
        fs::write(&p, SAMPLE).unwrap();
        let mut at = None;
        run(&p, Opts::default(), &mut |pt| match pt {
            Point::AfterExchange(_) => at = Some(std::time::Instant::now()),
            Point::Checked => times.push(at.unwrap().elapsed()),
            _ => {}
        });
    }
    times.sort();
    let q = |f: f64| times[((times.len() - 1) as f64 * f) as usize];
    eprintln!(
        "window: median {:?}, p99 {:?}, max {:?} ({} runs)",
        q(0.5),
        q(0.99),
        q(1.0),
        times.len()
    );
}

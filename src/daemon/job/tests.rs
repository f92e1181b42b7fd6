use super::*;

use crate::daemon::events::MemOut as Buf;
use crate::load::FileSource;

/// The events `after_panic` emits for a run that got to `state`: (event, run_id).
fn after_panic_at(state: u8) -> Vec<(String, u64)> {
    let buf = Buf::default();
    let sink = EventSink::to(Box::new(buf.clone()));
    let progress = Progress::default();
    progress.set(state);
    after_panic(&sink, Path::new("/p"), 7, "change", &progress);
    assert_eq!(progress.get(), FINISHED);
    sink.flush(Duration::from_secs(2));
    let text = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
    text.lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            assert_eq!(v["project"], "/p");
            (
                v["event"].as_str().unwrap().to_owned(),
                v["run_id"].as_u64().unwrap(),
            )
        })
        .collect()
}

/// Reads from disk, but the SFC's first open finds it empty (truncated by a save) and the
/// save's bytes land right after: what an in-place `write` racing the compile looks like.
struct SavedDuring {
    fs: FsSource,
    sfc: PathBuf,
    opened: std::sync::atomic::AtomicBool,
}

impl FileSource for SavedDuring {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        self.fs.read(path)
    }

    fn open(&self, path: &Path) -> std::io::Result<crate::load::Opened<'_>> {
        if path == self.sfc && !self.opened.swap(true, std::sync::atomic::Ordering::SeqCst) {
            let full = std::fs::read(path)?;
            let o = crate::load::Opened {
                len: Some(0),
                reader: Box::new(std::io::Cursor::new(Vec::new())),
                at: None,
            };
            std::fs::write(path, full)?;
            return Ok(o);
        }
        self.fs.open(path)
    }
}

/// Another program's write lease on the blackboard (a file server's oplock) refuses the
/// hash check's open until its holder lets go: the check waits for that instead of taking
/// the file for changed.
#[test]
fn a_hash_check_waits_for_a_lease_to_be_given_up() {
    use crate::write::writeback::lease;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("Blackboard.aml");
    std::fs::write(&p, "<CAEXFile/>").unwrap();
    if !lease::leases_work(dir.path()) {
        return;
    }
    let held = lease::Unleased(std::fs::File::open(&p).unwrap());
    assert!(matches!(lease::take(&held), Ok(true)));
    // The holder: lets go when the kernel asks it to (the check's open starts that), as
    // a file server does.
    let holder = std::thread::spawn(move || {
        let start = std::time::Instant::now();
        while lease::intact(&held.0) && start.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(1));
        }
        drop(held);
    });
    let during = hash_file(&p);
    holder.join().unwrap();
    assert!(
        during.is_some(),
        "the check took the leased file for unreadable"
    );
    assert_eq!(during, hash_file(&p));
}

#[test]
fn an_sfc_read_empty_by_a_racing_save_is_still_being_written() {
    let dir = tempfile::tempdir().unwrap();
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample");
    for f in ["Blackboard.aml", "sfc.xml", "kr15-2.irl"] {
        std::fs::copy(sample.join(f), dir.path().join(f)).unwrap();
    }
    let sfc = dir.path().join("sfc.xml");
    let fs = SavedDuring {
        fs: FsSource::default(),
        sfc: sfc.clone(),
        opened: Default::default(),
    };
    let c = crate::compile::compile(
        &fs,
        &dir.path().join("Blackboard.aml"),
        &crate::compile::Options::default(),
    );
    assert!(c.has_errors(), "an empty SFC does not compile");
    // What `Hashing` records for the empty bytes the compile read.
    let read = HashMap::from([(sfc.clone(), Some(crate::load::ContentHash::new().finish()))]);
    // The file's text is not the one compiled, so the error has no line, but it still names
    // the file: the daemon tries again instead of failing the run.
    assert_eq!(half_written(&c, &read, false), Some((sfc, true)));
}

#[test]
fn an_sfc_truncated_by_a_writer_that_has_not_written_yet_is_still_being_written() {
    // An in-place save opened the SFC with truncation and has not written yet (a loaded
    // machine can hold it there for longer than any short look again): the file is empty
    // and unchanged since the compile read it, but it is open for writing.
    let dir = tempfile::tempdir().unwrap();
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample");
    for f in ["Blackboard.aml", "sfc.xml", "kr15-2.irl"] {
        std::fs::copy(sample.join(f), dir.path().join(f)).unwrap();
    }
    let sfc = dir.path().join("sfc.xml");
    let writer = std::fs::File::options()
        .write(true)
        .truncate(true)
        .open(&sfc)
        .unwrap();
    let c = crate::compile::compile(
        &FsSource::default(),
        &dir.path().join("Blackboard.aml"),
        &crate::compile::Options::default(),
    );
    assert!(c.has_errors(), "an empty SFC does not compile");
    let read = HashMap::from([(sfc.clone(), Some(crate::load::ContentHash::new().finish()))]);
    assert!(
        half_written(&c, &read, false).is_some(),
        "a save in progress"
    );
    // The writer closes without writing: an empty SFC, complete (the next save compiles).
    drop(writer);
    let aged = std::time::SystemTime::now() - Duration::from_secs(5);
    std::fs::File::options()
        .write(true)
        .open(&sfc)
        .unwrap()
        .set_modified(aged)
        .unwrap();
    assert_eq!(half_written(&c, &read, false), None);
}

#[test]
fn a_panic_completes_the_run_with_exactly_one_outcome() {
    let started = ("compile-started".to_owned(), 7);
    let failed = ("compile-failed".to_owned(), 7);
    // Before `compile-started` (e.g. in the hash check): the run is started, then failed.
    assert_eq!(after_panic_at(0), vec![started, failed.clone()]);
    // After it: only the outcome.
    assert_eq!(after_panic_at(STARTED), vec![failed]);
    // After the outcome (e.g. in the write-back): no second outcome.
    assert_eq!(after_panic_at(FINISHED), vec![]);
}

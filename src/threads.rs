//! Work split in two: one part on the calling thread, the other on a thread of its own.

/// Runs `here` on the calling thread and `there` on a thread named `name`, at the same time, and
/// returns both results. Where no thread can be started, `there` runs here after `here`. A panic
/// on the other thread goes on here.
pub fn both<A, B: Send>(
    name: &str,
    here: impl FnOnce() -> A,
    there: impl Fn() -> B + Sync,
) -> (A, B) {
    std::thread::scope(|s| {
        let started = std::thread::Builder::new()
            .name(name.to_owned())
            .spawn_scoped(s, &there);
        let a = here();
        let b = match started {
            Ok(h) => h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)),
            Err(_) => there(),
        };
        (a, b)
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn both_parts_run_and_the_other_on_a_thread_of_its_own() {
        let caller = std::thread::current().id();
        let (a, b) = super::both(
            "skillpost-test",
            || (std::thread::current().id(), 1),
            || {
                let t = std::thread::current();
                (t.id(), t.name().map(str::to_owned), 2)
            },
        );
        assert_eq!(a, (caller, 1));
        assert_ne!(b.0, caller);
        assert_eq!((b.1.as_deref(), b.2), (Some("skillpost-test"), 2));
    }

    #[test]
    #[should_panic(expected = "there")]
    fn a_panic_on_the_other_thread_goes_on_here() {
        super::both("skillpost-test", || (), || panic!("there"));
    }
}

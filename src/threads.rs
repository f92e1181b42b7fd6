//! Work shared by the calling thread and one thread of its own: in two parts ([`both`]), in
//! pieces that each takes in turn ([`pieces`]), or item by item, the largest first
//! ([`largest_first`]: a cell's programs, generated files).

use std::sync::atomic::{AtomicUsize, Ordering};

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

/// `work` over `items` cut into `pieces` pieces (about equal; fewer when there are fewer items),
/// on the calling thread and a thread named `name` at once, each taking the next piece when it
/// is done with one: a core that runs slower (a busy or shared one) takes fewer, and neither
/// waits long for the other at the end. `work` gets the index of the piece's first item and
/// the piece. The results in the pieces' order, whichever thread made them.
pub fn pieces<T: Sync, R: Send>(
    name: &str,
    items: &[T],
    pieces: usize,
    work: impl Fn(usize, &[T]) -> R + Sync,
) -> Vec<R> {
    let len = items.len().div_ceil(pieces.max(1)).max(1);
    let count = items.len().div_ceil(len);
    let next = AtomicUsize::new(0);
    let take = || {
        let mut done = Vec::new();
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            if k >= count {
                break;
            }
            let end = items.len().min((k + 1) * len);
            done.push((k, work(k * len, &items[k * len..end])));
        }
        done
    };
    let (mut done, there) = both(name, take, take);
    done.extend(there);
    done.sort_unstable_by_key(|&(k, _)| k);
    done.into_iter().map(|(_, r)| r).collect()
}

/// `work(k)` for each item `k` of `sizes.len()`, on the calling thread and a thread named `name`
/// at once, the largest items (by `sizes`) first, each thread taking the next when done with
/// one ([`pieces`] of one item): the last item either takes is a small one. The results in the
/// items' order.
pub fn largest_first<R: Send>(
    name: &str,
    sizes: &[usize],
    work: impl Fn(usize) -> R + Sync,
) -> Vec<R> {
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&k| std::cmp::Reverse(sizes[k]));
    let made = pieces(name, &order, order.len(), |_, ks| {
        ks.iter().map(|&k| (k, work(k))).collect::<Vec<_>>()
    });
    let mut out: Vec<Option<R>> = (0..sizes.len()).map(|_| None).collect();
    for (k, r) in made.into_iter().flatten() {
        out[k] = Some(r);
    }
    out.into_iter().flatten().collect()
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
    fn largest_first_gives_the_results_in_the_items_order() {
        for sizes in [vec![], vec![3], vec![1, 9, 4, 9, 0, 7, 2], vec![5; 40]] {
            let got = super::largest_first("skillpost-test", &sizes, |k| (k, sizes[k] * 10));
            let want: Vec<(usize, usize)> = sizes.iter().map(|&s| s * 10).enumerate().collect();
            assert_eq!(got, want, "sizes {sizes:?}");
        }
    }

    #[test]
    #[should_panic(expected = "there")]
    fn a_panic_on_the_other_thread_goes_on_here() {
        super::both("skillpost-test", || (), || panic!("there"));
    }

    #[test]
    fn pieces_come_back_in_order_whoever_made_them() {
        let items: Vec<u32> = (0..1000).collect();
        for pieces in [1, 2, 7, 32, 999, 1000, 5000] {
            let made = super::pieces("skillpost-test", &items, pieces, |from, some| {
                assert_eq!(some.first(), items.get(from));
                some.to_vec()
            });
            assert!((1..=pieces).contains(&made.len()), "{pieces} pieces");
            let joined: Vec<u32> = made.into_iter().flatten().collect();
            assert_eq!(joined, items, "{pieces} pieces");
        }
        // Nothing to do: no piece.
        assert!(super::pieces("skillpost-test", &[] as &[u32], 4, |_, s| s.len()).is_empty());
    }

    #[test]
    fn a_slow_thread_takes_fewer_pieces() {
        // The other thread is slowed down: the calling thread takes most pieces, instead of
        // waiting for the other's half.
        let caller = std::thread::current().id();
        let items: Vec<u32> = (0..64).collect();
        let made = super::pieces("skillpost-test", &items, 64, |_, _| {
            let here = std::thread::current().id() == caller;
            if !here {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            here
        });
        let here = made.iter().filter(|&&h| h).count();
        assert!(here > 48, "the calling thread made {here} of 64 pieces");
    }
}

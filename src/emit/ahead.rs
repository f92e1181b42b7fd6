//! A long program's steps read on a second thread, ahead of the writer.
//!
//! What can be read of a step before its points are named needs no state of the program: its
//! code's motions to literal targets and the base of their names ([`ReadAhead`]), and its
//! title after its number ([`super::flow::push_title_tail`]). That is about a third of writing
//! a step (KRL: the motion's parse, the title). The program's points are named in the order the
//! steps are written, which only the writer knows as it goes; so a second thread reads the steps
//! in program order ([`crate::plan::visit`]), batch by batch, and the writer takes each step's
//! reading when it writes the step. A step the writer does not find so (a branch it never
//! writes, a step written in an order of its own, a thread that is behind) it reads itself: the
//! text is the same either way.
//!
//! Memory stays flat: at most `QUEUE` batches of `BATCH` steps are read ahead, and emptied
//! batches go back to the reading thread. When the writer is done, the thread stops at its next
//! batch.

use std::ops::Range;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use super::EmitInput;
use super::points::ReadAhead;
use crate::lang::Language;
use crate::plan::Block;

/// Steps in a batch.
const BATCH: usize = 256;
/// Batches read and not yet taken by the writer.
const QUEUE: usize = 4;

/// Steps read ahead, in program order.
#[derive(Default)]
pub struct Batch {
    /// Their code.
    pub read: ReadAhead,
    titles: String,
    /// Each step's title after its number, in `titles`; `None` when it is not ASCII on one line
    /// (the writer makes the whole title then).
    title: Vec<Option<Range<usize>>>,
}

impl Batch {
    /// Reads step `i` of `input` for a program in `lang`.
    fn read(&mut self, input: &EmitInput, lang: Language, i: usize, bs: &crate::bind::BoundStep) {
        self.read
            .read(lang, i, super::flow::step_name(input, i), &bs.code);
        let at = self.titles.len();
        super::flow::push_title_tail(&mut self.titles, input, i, bs);
        if super::flow::is_clean(&self.titles[at..]) {
            self.title.push(Some(at..self.titles.len()));
        } else {
            self.titles.truncate(at);
            self.title.push(None);
        }
    }

    /// The title after its number of item `k`, when it is ASCII on one line.
    pub fn title(&self, k: usize) -> Option<&str> {
        self.title[k].clone().map(|r| &self.titles[r])
    }

    fn len(&self) -> usize {
        self.read.items.len()
    }

    fn clear(&mut self) {
        self.read.clear();
        self.titles.clear();
        self.title.clear();
    }
}

/// The writer's end: the batches read so far, in program order.
pub struct Ahead {
    rx: Receiver<Batch>,
    /// Emptied batches, back to the reading thread.
    back: SyncSender<Batch>,
    cur: Batch,
    /// The next item of `cur` to look at.
    k: usize,
}

impl Ahead {
    /// The item of step `i`: the next one read for `i`, items before it passed over. `None`
    /// when the steps read so far do not hold it: then the writer reads the step itself. It
    /// never waits for the reading thread: where that thread is behind (its core busy with
    /// something else, or it has just started), the writer goes on alone, and the steps the
    /// thread read meanwhile are passed over when it catches up.
    pub fn find(&mut self, i: usize) -> Option<usize> {
        loop {
            while self.k < self.cur.len() {
                let k = self.k;
                self.k += 1;
                if self.cur.read.items[k].step == i {
                    return Some(k);
                }
            }
            let next = self.rx.try_recv().ok()?;
            let mut old = std::mem::replace(&mut self.cur, next);
            old.clear();
            let _ = self.back.try_send(old);
            self.k = 0;
        }
    }

    /// The batch [`Ahead::find`] found its item in.
    pub fn batch(&self) -> &Batch {
        &self.cur
    }
}

/// Starts reading `input`'s steps for a program in `lang` on a thread of `scope`; `None` when
/// no thread can be started (the writer reads every step itself). The thread ends when every
/// step is read or the [`Ahead`] is dropped.
pub fn start<'scope, 'env, 'a: 'env>(
    scope: &'scope std::thread::Scope<'scope, 'env>,
    input: &'env EmitInput<'a>,
    lang: Language,
) -> Option<Ahead> {
    let (tx, rx) = sync_channel::<Batch>(QUEUE);
    let (back, back_rx) = sync_channel::<Batch>(QUEUE + 2);
    std::thread::Builder::new()
        .name("skillpost-read-ahead".into())
        .spawn_scoped(scope, move || {
            let mut batch = Batch::default();
            let mut gone = false;
            crate::plan::visit(input.body, &mut |b| {
                let Block::Step(i) = b else { return };
                let Some(bs) = input.bound.steps.get(*i) else {
                    return;
                };
                if gone {
                    return;
                }
                batch.read(input, lang, *i, bs);
                if batch.len() == BATCH {
                    let next = back_rx.try_recv().unwrap_or_default();
                    // The writer has ended (its `Ahead` dropped): nothing more to read.
                    gone = tx.send(std::mem::replace(&mut batch, next)).is_err();
                }
            });
            if !gone && batch.len() > 0 {
                let _ = tx.send(batch);
            }
        })
        .ok()?;
    Some(Ahead {
        rx,
        back,
        cur: Batch::default(),
        k: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An [`Ahead`] over batches of the steps `batches` (their code without a literal target).
    fn ahead_of(batches: &[&[usize]]) -> Ahead {
        let (tx, rx) = sync_channel(batches.len());
        let (back, _back_rx) = sync_channel(batches.len());
        for steps in batches {
            let mut b = Batch::default();
            for &i in *steps {
                b.read.read(Language::Krl, i, "Step", "WAIT SEC 0");
                b.title.push(None);
            }
            tx.send(b).unwrap();
        }
        drop(tx);
        // (`_back_rx` dropped: returned batches are let go.)
        Ahead {
            rx,
            back,
            cur: Batch::default(),
            k: 0,
        }
    }

    #[test]
    fn the_writer_finds_its_steps_in_order_and_passes_over_steps_it_does_not_write() {
        let mut a = ahead_of(&[&[1, 2, 3], &[4, 5], &[6]]);
        let found = |a: &mut Ahead, i| a.find(i).map(|k| a.batch().read.items[k].step);
        assert_eq!(found(&mut a, 1), Some(1));
        // Step 2 in a branch the writer never writes: passed over.
        assert_eq!(found(&mut a, 3), Some(3));
        // Across batches.
        assert_eq!(found(&mut a, 5), Some(5));
        // A step that is not read ahead (or not again): every batch looked at, none holds it;
        // the writer reads it itself, and the rest too.
        assert_eq!(found(&mut a, 9), None);
        assert_eq!(found(&mut a, 6), None);
    }

    #[test]
    fn the_writer_never_waits_for_a_reading_thread_that_is_behind() {
        let (tx, rx) = sync_channel(2);
        let (back, _back_rx) = sync_channel(2);
        let mut a = Ahead {
            rx,
            back,
            cur: Batch::default(),
            k: 0,
        };
        // Nothing read yet: the writer writes steps 1 and 2 itself.
        assert_eq!(a.find(1), None);
        assert_eq!(a.find(2), None);
        let mut b = Batch::default();
        for i in 1..=4 {
            b.read.read(Language::Krl, i, "Step", "WAIT SEC 0");
            b.title.push(None);
        }
        tx.send(b).unwrap();
        // Steps 1 and 2, read meanwhile, are passed over.
        assert_eq!(a.find(3).map(|k| a.batch().read.items[k].step), Some(3));
        assert_eq!(a.find(4).map(|k| a.batch().read.items[k].step), Some(4));
        assert_eq!(a.find(5), None);
    }

    #[test]
    fn a_step_is_read_ahead_as_the_writer_reads_it() {
        let mut r = ReadAhead::default();
        r.read(
            Language::Krl,
            7,
            "Pick Part",
            "SetVel (1)\n  PTP {X 1, Y 2, Z 3, A 0, B 0, C 0} C_PTP",
        );
        r.read(Language::Krl, 8, "Wait", "WAIT SEC 1");
        let mut p = super::super::points::Points::new(
            Language::Krl,
            super::super::points::Mode::Named,
            super::super::points::KrlForm::Named,
            Vec::new(),
        );
        let mut q = super::super::points::Points::new(
            Language::Krl,
            super::super::points::Mode::Named,
            super::super::points::KrlForm::Named,
            Vec::new(),
        );
        for (k, (name, code)) in [
            (
                "Pick Part",
                "SetVel (1)\n  PTP {X 1, Y 2, Z 3, A 0, B 0, C 0} C_PTP",
            ),
            ("Wait", "WAIT SEC 1"),
        ]
        .into_iter()
        .enumerate()
        {
            let theirs = p.step_code(name, code).to_owned();
            let ours = q.step_code_read(code, &r, k).to_owned();
            assert_eq!(ours, theirs);
        }
        assert_eq!(p.declarations, q.declarations);
        assert_eq!(q.declarations.len(), 1);
        assert!(
            q.declarations[0].starts_with("DECL E6POS XPickPart="),
            "{:?}",
            q.declarations
        );
    }
}

//! The cell split (docs/CELLS.md): the program tree of a chart whose steps run on several
//! controllers → one tree per controller, with the handshakes that keep the chart's order
//! between them.
//!
//! How it works, in one walk over the tree in program order:
//!
//! - Each controller has a clock that ticks when it finishes a step (or passes a wait or a
//!   construct), and knows, for every other controller, up to which tick that one has come
//!   (`know`, a vector clock). What the next block depends on is a *frontier*: points
//!   (controller, tick) — the steps the chart puts right before it.
//! - Before a controller runs a block it *acquires* the frontier: for each point of another
//!   controller it does not know to be passed yet, the other controller tells it (a
//!   [`Block::Tell`] at the other's current place) and it waits for that (a [`Block::Hear`] at
//!   its own). Hearing merges the teller's knowledge: nothing is waited for twice, and nothing
//!   the chart does not put before the block is waited for.
//! - A selection is decided by the controller of the step before it (the decider); every other
//!   controller that takes part (has a step, a wait or a decision in it; for a selection that
//!   leaves or repeats a loop, every controller of the loop) follows it: the decider tells each
//!   the branch's index first thing in the branch, each waits for that before the branches
//!   ([`Block::Follow`]). A loop is run by the controllers that take part in it; they all
//!   acquire what comes before it on entry, and at the end of a round (a branch that repeats,
//!   or the body of an endless loop) what the next round's first step waits for.
//! - After a selection or a loop, what follows depends on every controller that took part
//!   having passed it (which branch ran is not known when the programs are written).
//!
//! Every handshake's tell and hear stand in the same place of the control flow of their two
//! programs (both run it equally often), and the walk's own order is one run of all programs
//! in which every message is heard right after it is told. So with one message in flight per
//! channel (the sender waits for the acknowledgement of the last one before it tells the next),
//! the programs never deadlock and always take the same branches, whatever their speeds: they
//! are a Kahn network, whose result does not depend on the timing.

use std::collections::{BTreeSet, HashMap};

use super::{Block, Branch, BranchEnd};

mod wires;
pub use wires::{assign_wires, wire_counts};

/// What a handshake message says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The step (or wait, or construct) `about` is done.
    Done,
    /// The selection at divergence `about` took branch `value` (from 0).
    Decision,
    /// The teller has come past a construct: a loop (`about`: its first step), a selection
    /// (its divergence; for the decider, once it has decided) or states (their first step).
    /// It may have run steps since the ones before it; a partner waits for the construct.
    Passed(Construct),
}

/// What a [`Kind::Passed`] message's teller has come past.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Construct {
    Loop,
    Selection,
    /// The decider has decided the selection (the points inside its branches).
    Decided,
    States,
    /// The barrier where states begin (`about`: the first state's step).
    Enter,
    /// The barrier at a jump between states (`about`: the step it goes on at).
    Jump,
}

impl Construct {
    /// Its name in `-pO`'s JSON (`"passed"`).
    pub fn name(self) -> &'static str {
        match self {
            Construct::Loop => "loop",
            Construct::Selection => "selection",
            Construct::Decided => "decision",
            Construct::States => "states",
            Construct::Enter => "states-entered",
            Construct::Jump => "jump",
        }
    }

    /// What the teller has done, before the element's name: `has left the loop at` step 'S'.
    pub fn verb(self) -> &'static str {
        match self {
            Construct::Loop => "has left the loop at",
            Construct::Selection => "has passed the selection",
            Construct::Decided => "has decided the selection",
            Construct::States => "has left the states from",
            Construct::Enter => "has come to the states from",
            Construct::Jump => "has come to the jump to",
        }
    }
}

/// One handshake message on a [`Channel`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Message {
    /// Index into [`Cell::channels`].
    pub channel: usize,
    pub kind: Kind,
    /// For a decision, the branch's index.
    pub value: usize,
    /// The element it is about: the step done, or the selection's divergence.
    pub about: usize,
}

/// Messages from one controller to another: the sender's strobe (toggled once per message),
/// the data bits of a decision, the receiver's acknowledgement (toggled when it has read one).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Channel {
    /// Indexes into [`Cell::controllers`].
    pub from: usize,
    pub to: usize,
    /// The largest decision value sent (0 when none or only `Done`).
    pub max_value: usize,
    /// Whether any decision is sent.
    pub decisions: bool,
    /// The first message's `about` (to locate a diagnostic).
    pub first_about: usize,
    /// The wires it uses once assigned ([`assign_wires`]): indexes into `Blackboard::wires`.
    pub strobe: Option<usize>,
    pub data: Vec<usize>,
    pub ack: Option<usize>,
}

impl Channel {
    /// The data bits a decision needs.
    pub fn data_bits(&self) -> usize {
        if !self.decisions {
            return 0;
        }
        (usize::BITS - self.max_value.leading_zeros()).max(1) as usize
    }
}

/// One controller's program.
#[derive(Debug, Clone)]
pub struct Program {
    /// Index into [`Cell::controllers`].
    pub controller: usize,
    pub body: Vec<Block>,
}

/// The programs of a cell.
#[derive(Debug, Clone, Default)]
pub struct Cell {
    /// The controllers' resources (indexes into the blackboard's), the first one's steps
    /// first in the chart.
    pub controllers: Vec<usize>,
    /// One per controller, in the same order.
    pub programs: Vec<Program>,
    pub channels: Vec<Channel>,
    /// One per ordered pair of partners (controllers with a channel either way), sorted.
    pub links: Vec<Link>,
}

/// What one controller tells a partner about itself, for the start barrier and the restart
/// guard (`emit::handshake` writes the protocol; `docs/CELLS.md` argues why it is safe): its
/// **run** wire is `FALSE` from its start until it has met all its partners at the start
/// barrier, `TRUE` while it runs its cycle (and after its end, until it is started again);
/// its **ready** wire is `TRUE` only inside the barrier, once it has seen every partner at
/// its start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Link {
    /// Indexes into [`Cell::controllers`]: the wires run `from` → `to`.
    pub from: usize,
    pub to: usize,
    /// Indexes into `Blackboard::wires` once assigned ([`assign_wires`]).
    pub run: Option<usize>,
    pub ready: Option<usize>,
}

impl Cell {
    /// The link from `a` to `b`, when they are partners.
    pub fn link(&self, a: usize, b: usize) -> Option<&Link> {
        self.links.iter().find(|l| (l.from, l.to) == (a, b))
    }

    /// The partners of controller `c`, in controller order.
    pub fn partners(&self, c: usize) -> impl Iterator<Item = usize> + '_ {
        self.links.iter().filter(move |l| l.from == c).map(|l| l.to)
    }
}

type Set = BTreeSet<usize>;

/// A point of a controller's program: (controller, tick, the element it is about, what a
/// message about it says).
type Point = (usize, u32, usize, Kind);

/// Splits the planned `body` into one program per controller. `controller(step)` is the
/// controller index (into `controllers`) running a step, `None` for a step without code (the
/// start and end steps may name no skill).
pub fn split(
    body: &[Block],
    controllers: Vec<usize>,
    controller: &dyn Fn(usize) -> Option<usize>,
) -> Cell {
    let n = controllers.len();
    let mut scan = Scan {
        controller,
        deciders: HashMap::new(),
        evaluators: HashMap::new(),
        choice_parts: HashMap::new(),
        loop_parts: HashMap::new(),
        machine_parts: HashMap::new(),
    };
    let mut all = Set::new();
    scan.blocks(body, 0, &mut all);
    let mut s = Splitter {
        scan,
        n,
        stacks: (0..n).map(|_| vec![Vec::new()]).collect(),
        clock: vec![0; n],
        know: vec![vec![0; n]; n],
        channels: Vec::new(),
        by_pair: HashMap::new(),
        loops: Vec::new(),
        machines: Vec::new(),
        last: vec![(0, Kind::Done); n],
    };
    s.blocks(body, Vec::new());
    let programs = s
        .stacks
        .into_iter()
        .enumerate()
        .map(|(c, mut st)| Program {
            controller: c,
            body: st.pop().unwrap_or_default(),
        })
        .collect();
    let mut links: Vec<Link> = s
        .channels
        .iter()
        .flat_map(|ch| [(ch.from, ch.to), (ch.to, ch.from)])
        .collect::<BTreeSet<_>>()
        .into_iter()
        .map(|(from, to)| Link {
            from,
            to,
            run: None,
            ready: None,
        })
        .collect();
    links.sort_by_key(|l| (l.from, l.to));
    Cell {
        controllers,
        programs,
        channels: s.channels,
        links,
    }
}

/// The first pass: who decides each selection, who evaluates each wait, who takes part in each
/// selection and loop.
struct Scan<'a> {
    controller: &'a dyn Fn(usize) -> Option<usize>,
    /// Selection divergence → its decider.
    deciders: HashMap<usize, usize>,
    /// Transition → the controller that waits for it.
    evaluators: HashMap<usize, usize>,
    /// Selection divergence → the controllers in it (its decider included).
    choice_parts: HashMap<usize, Set>,
    /// Loop head → the controllers in it.
    loop_parts: HashMap<usize, Set>,
    /// A machine's first state's entry → the controllers in it.
    machine_parts: HashMap<usize, Set>,
}

impl Scan<'_> {
    /// Scans a sequence; `ctx` is the controller in charge at its start (the last step's, or
    /// the decider's); returns the one in charge at its end. Every controller met goes into
    /// `set`.
    fn blocks(&mut self, blocks: &[Block], mut ctx: usize, set: &mut Set) -> usize {
        for (k, b) in blocks.iter().enumerate() {
            match b {
                Block::Machine(states) => {
                    // Each state starts with the controller in charge where the machine
                    // starts (which state went there is not known when writing).
                    let mut own = Set::from([ctx]);
                    for st in states {
                        self.blocks(&st.body, ctx, &mut own);
                    }
                    // Every controller of the machine goes to the same states: it takes part
                    // in each selection and loop that goes to another state.
                    self.share_gotos(states, &own);
                    set.extend(own.iter().copied());
                    if let Some(first) = states.first() {
                        self.machine_parts.insert(first.entry, own);
                    }
                }
                Block::Goto { .. } => {}
                Block::Step(i) => {
                    if let Some(c) = (self.controller)(*i) {
                        ctx = c;
                        set.insert(c);
                    }
                }
                Block::Wait(t) => {
                    // Waited for by the controller of the step after it (docs/CELLS.md), else by
                    // the one in charge.
                    let c = match blocks.get(k + 1) {
                        Some(Block::Step(j)) => (self.controller)(*j).unwrap_or(ctx),
                        _ => ctx,
                    };
                    self.evaluators.insert(*t, c);
                    set.insert(c);
                }
                Block::Parallel { branches, .. } => {
                    let mut last = ctx;
                    for br in branches {
                        last = self.blocks(br, ctx, set);
                    }
                    ctx = last;
                }
                Block::Sequences(seqs) => {
                    // Each sequence is in the charge of its own first controller.
                    for seq in seqs {
                        let first = super::first_step(seq, self.controller);
                        ctx = self.blocks(seq, first.unwrap_or(ctx), set);
                    }
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                } => {
                    self.deciders.insert(*divergence, ctx);
                    let mut own = Set::from([ctx]);
                    for br in branches {
                        self.blocks(&br.body, ctx, &mut own);
                    }
                    set.extend(own.iter().copied());
                    self.choice_parts.insert(*divergence, own);
                }
                Block::Loop { head, body, .. } => {
                    let mut own = Set::new();
                    ctx = self.blocks(body, ctx, &mut own);
                    set.extend(own.iter().copied());
                    self.loop_parts.insert(*head, own);
                }
                Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => {}
            }
        }
        ctx
    }
}

impl Scan<'_> {
    /// Adds `parts` to every selection and loop of `states` (not of a nested machine) that
    /// holds a Goto.
    fn share_gotos(&mut self, states: &[super::State], parts: &Set) {
        fn walk(scan: &mut Scan, blocks: &[Block], parts: &Set) {
            for b in blocks {
                let mut targets = Vec::new();
                super::gotos(std::slice::from_ref(b), &mut targets);
                if targets.is_empty() {
                    continue;
                }
                match b {
                    Block::Choice {
                        divergence,
                        branches,
                        ..
                    } => {
                        if let Some(p) = scan.choice_parts.get_mut(divergence) {
                            p.extend(parts.iter().copied());
                        }
                        for br in branches {
                            walk(scan, &br.body, parts);
                        }
                    }
                    Block::Loop { head, body, .. } => {
                        if let Some(p) = scan.loop_parts.get_mut(head) {
                            p.extend(parts.iter().copied());
                        }
                        walk(scan, body, parts);
                    }
                    Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                        for br in branches {
                            walk(scan, br, parts);
                        }
                    }
                    _ => {}
                }
            }
        }
        for st in states {
            walk(self, &st.body, parts);
        }
    }
}

/// Whether a selection leaves or repeats the loop it stands in (a branch of it, or of a
/// selection inside it, not inside a nested loop, ends in a leave or a repeat).
fn ends_rounds(branches: &[Branch]) -> bool {
    fn inside(b: &Block) -> bool {
        match b {
            Block::Choice { branches, .. } => ends_rounds(branches),
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                branches.iter().flatten().any(inside)
            }
            _ => false,
        }
    }
    branches
        .iter()
        .any(|br| br.end != BranchEnd::Join || br.body.iter().any(inside))
}

struct Splitter<'a> {
    scan: Scan<'a>,
    n: usize,
    /// Per controller: the bodies being written, innermost last.
    stacks: Vec<Vec<Vec<Block>>>,
    clock: Vec<u32>,
    /// `know[c][d]`: the tick of `d` that `c` knows `d` has passed.
    know: Vec<Vec<u32>>,
    channels: Vec<Channel>,
    by_pair: HashMap<(usize, usize), usize>,
    /// The controllers of each enclosing loop, innermost last.
    loops: Vec<Set>,
    /// The controllers of each enclosing [`Block::Machine`], innermost last.
    machines: Vec<Set>,
    /// Per controller, what its latest tick is about.
    last: Vec<(usize, Kind)>,
}

impl Splitter<'_> {
    fn push(&mut self, c: usize, b: Block) {
        if let Some(top) = self.stacks[c].last_mut() {
            top.push(b);
        }
    }

    fn tick(&mut self, c: usize, about: usize, kind: Kind) -> u32 {
        self.last[c] = (about, kind);
        self.clock[c] += 1;
        self.know[c][c] = self.clock[c];
        self.clock[c]
    }

    fn channel(&mut self, from: usize, to: usize, about: usize) -> usize {
        let next = self.channels.len();
        let ch = *self.by_pair.entry((from, to)).or_insert(next);
        if ch == next {
            self.channels.push(Channel {
                from,
                to,
                max_value: 0,
                decisions: false,
                first_about: about,
                strobe: None,
                data: Vec::new(),
                ack: None,
            });
        }
        ch
    }

    /// `to` learns all `from` knows.
    fn merge(&mut self, from: usize, to: usize) {
        for d in 0..self.n {
            let k = self.know[from][d];
            if self.know[to][d] < k {
                self.know[to][d] = k;
            }
        }
    }

    /// `c` waits until every point of the frontier has been passed.
    fn acquire(&mut self, c: usize, frontier: &[Point]) {
        for &(d, t, ..) in frontier {
            if d == c || self.know[c][d] >= t {
                continue;
            }
            // The tell stands at `d`'s place now, which may be past the point (its steps in an
            // earlier simultaneous branch, a loop left): it says what `d` has done last, which
            // the point is part of, so its comment and message are true where they stand.
            let (about, kind) = self.last[d];
            let channel = self.channel(d, c, about);
            let m = Message {
                channel,
                kind,
                value: 0,
                about,
            };
            self.push(d, Block::Tell(m));
            self.push(c, Block::Hear(m));
            self.merge(d, c);
        }
    }

    /// Tell at once: a branch of a simultaneous divergence that begins with a step (or a
    /// wait) of a controller with nothing in the branches before it waits for what the
    /// divergence waits for before any branch is written. So the teller tells right after its
    /// step before the divergence, not after its own steps in an earlier branch (which the
    /// partner does not wait for). The hear stands where that controller's part of the block
    /// begins, as it would when its branch is written; this is still one run of all programs
    /// in which every message is heard right after it is told.
    fn tell_at_once(&mut self, branches: &[Vec<Block>], frontier: &[Point]) {
        let mut before = Set::new();
        for br in branches {
            let first = match br.first() {
                Some(Block::Step(i)) => (self.scan.controller)(*i),
                Some(Block::Wait(t)) => self.scan.evaluators.get(t).copied(),
                _ => None,
            };
            if let Some(c) = first
                && !before.contains(&c)
            {
                self.acquire(c, frontier);
            }
            self.involved(br, &mut before);
        }
    }

    /// Every controller with a step, a wait or a decision in `blocks`.
    fn involved(&self, blocks: &[Block], set: &mut Set) {
        for b in blocks {
            match b {
                Block::Step(i) => set.extend((self.scan.controller)(*i)),
                Block::Wait(t) => set.extend(self.scan.evaluators.get(t).copied()),
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    for br in branches {
                        self.involved(br, set);
                    }
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                } => {
                    set.extend(self.scan.choice_parts.get(divergence).into_iter().flatten());
                    for br in branches {
                        self.involved(&br.body, set);
                    }
                }
                Block::Loop { head, body, .. } => {
                    set.extend(self.scan.loop_parts.get(head).into_iter().flatten());
                    self.involved(body, set);
                }
                Block::Machine(states) => {
                    for st in states {
                        self.involved(&st.body, set);
                    }
                }
                Block::Goto { .. } | Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => {}
            }
        }
    }

    /// Keeps the latest point of each controller (knowing it is knowing the earlier ones).
    fn latest(points: Vec<Point>) -> Vec<Point> {
        let mut out: Vec<Point> = Vec::new();
        for p in points {
            match out.iter_mut().find(|q| q.0 == p.0) {
                Some(q) if q.1 < p.1 => *q = p,
                Some(_) => {}
                None => out.push(p),
            }
        }
        out
    }

    fn blocks(&mut self, blocks: &[Block], mut frontier: Vec<Point>) -> Vec<Point> {
        for b in blocks {
            frontier = self.block(b, frontier);
        }
        frontier
    }

    fn block(&mut self, b: &Block, frontier: Vec<Point>) -> Vec<Point> {
        match b {
            Block::Machine(states) => self.machine(states, frontier),
            Block::Goto { target, from } => {
                // Every controller of the machine has come here before any goes on at the
                // target: a state starts with everything before it done.
                self.barrier(*target, Construct::Jump);
                if let Some(parts) = self.machines.last().cloned() {
                    for p in parts {
                        self.push(
                            p,
                            Block::Goto {
                                target: *target,
                                from: *from,
                            },
                        );
                    }
                }
                Vec::new()
            }
            // The frontier's list is used again for the point after (a step at a time: no
            // allocation per step).
            Block::Step(i) => {
                let Some(c) = (self.scan.controller)(*i) else {
                    return frontier;
                };
                self.acquire(c, &frontier);
                self.push(c, Block::Step(*i));
                let t = self.tick(c, *i, Kind::Done);
                let mut next = frontier;
                next.clear();
                next.push((c, t, *i, Kind::Done));
                next
            }
            Block::Wait(t) => {
                let c = self.scan.evaluators[t];
                self.acquire(c, &frontier);
                self.push(c, Block::Wait(*t));
                let k = self.tick(c, *t, Kind::Done);
                let mut next = frontier;
                next.clear();
                next.push((c, k, *t, Kind::Done));
                next
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                if matches!(b, Block::Parallel { .. }) {
                    self.tell_at_once(branches, &frontier);
                }
                // On each controller its parts of the branches run one after another.
                let mut out = Vec::new();
                for br in branches {
                    out.extend(self.blocks(br, frontier.clone()));
                }
                Self::latest(out)
            }
            Block::Choice {
                divergence,
                convergence,
                branches,
            } => self.choice(*divergence, *convergence, branches, frontier),
            Block::Loop {
                head,
                jumps,
                body,
                endless,
            } => {
                let parts = self.scan.loop_parts[head].clone();
                // Everything in the loop comes after what is before it: acquired on entry,
                // it holds in every round.
                for &p in &parts {
                    self.acquire(p, &frontier);
                }
                let entry = self.know.clone();
                for &p in &parts {
                    self.stacks[p].push(Vec::new());
                }
                self.loops.push(parts.clone());
                let end = self.blocks(body, frontier);
                if *endless {
                    // The next round's first step comes after this round's last.
                    for &p in &parts {
                        self.acquire(p, &end);
                    }
                }
                self.loops.pop();
                self.know = entry;
                let mut out = Vec::new();
                for &p in &parts {
                    let body = self.stacks[p].pop().unwrap_or_default();
                    self.push(
                        p,
                        Block::Loop {
                            head: *head,
                            jumps: jumps.clone(),
                            body,
                            endless: *endless,
                        },
                    );
                    let passed = Kind::Passed(Construct::Loop);
                    let t = self.tick(p, *head, passed);
                    out.push((p, t, *head, passed));
                }
                out
            }
            Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => frontier,
        }
    }

    /// Each controller of the innermost machine waits until every other has come as far as the
    /// walk has.
    /// The message says where (`about`, `what`): which state came before is not known when
    /// the programs are written, so not which step was done last.
    fn barrier(&mut self, about: usize, what: Construct) {
        let Some(parts) = self.machines.last().cloned() else {
            return;
        };
        for &d in &parts {
            self.last[d] = (about, Kind::Passed(what));
        }
        let points: Vec<Point> = parts
            .iter()
            .map(|&d| (d, self.clock[d], about, Kind::Passed(what)))
            .collect();
        for &c in &parts {
            self.acquire(c, &points);
        }
    }

    /// A machine (states and Gotos): its controllers enter it together; each state starts
    /// with everything before it done on every controller of the machine (a barrier where the
    /// machine starts and at every Goto), since which state came before is not known when the
    /// programs are written; every controller follows each decision that goes to another
    /// state, so all go to the same states. What follows depends on every controller of the
    /// machine having left it.
    fn machine(&mut self, states: &[super::State], frontier: Vec<Point>) -> Vec<Point> {
        let Some(first) = states.first() else {
            return frontier;
        };
        let parts = self.scan.machine_parts[&first.entry].clone();
        for &p in &parts {
            self.acquire(p, &frontier);
        }
        self.machines.push(parts.clone());
        self.barrier(first.entry, Construct::Enter);
        let entry = self.know.clone();
        let mut written: Vec<Vec<super::State>> = vec![Vec::new(); self.n];
        for st in states {
            // Everything before the state is done (the barriers): nothing before it is waited
            // for in it.
            for &c in &parts {
                for &d in &parts {
                    self.know[c][d] = self.clock[d];
                }
            }
            for &p in &parts {
                self.stacks[p].push(Vec::new());
            }
            self.blocks(&st.body, Vec::new());
            for &p in &parts {
                let body = self.stacks[p].pop().unwrap_or_default();
                written[p].push(super::State {
                    entry: st.entry,
                    body,
                });
            }
        }
        self.machines.pop();
        self.know = entry;
        // A state that ends without a Goto ends the machine; what follows waits for each
        // controller of the machine (as after a loop).
        let mut out = Vec::new();
        for &p in &parts {
            let states = std::mem::take(&mut written[p]);
            self.push(p, Block::Machine(states));
            let passed = Kind::Passed(Construct::States);
            let t = self.tick(p, first.entry, passed);
            out.push((p, t, first.entry, passed));
        }
        out
    }

    fn choice(
        &mut self,
        div: usize,
        convergence: Option<usize>,
        branches: &[Branch],
        frontier: Vec<Point>,
    ) -> Vec<Point> {
        let d = self.scan.deciders[&div];
        let mut parts = self.scan.choice_parts[&div].clone();
        if ends_rounds(branches)
            && let Some(l) = self.loops.last()
        {
            parts.extend(l.iter().copied());
        }
        // The decider decides once what comes before is done.
        self.acquire(d, &frontier);
        let decided = self.tick(d, div, Kind::Passed(Construct::Decided));
        let followers: Vec<usize> = parts.iter().copied().filter(|&p| p != d).collect();
        let channels: Vec<usize> = followers
            .iter()
            .map(|&f| {
                let ch = self.channel(d, f, div);
                let c = &mut self.channels[ch];
                c.decisions = true;
                c.max_value = c.max_value.max(branches.len().saturating_sub(1));
                ch
            })
            .collect();
        for &f in &followers {
            self.merge(d, f);
        }
        let after_decision = self.know.clone();
        // What each controller did last, as each branch begins (not the earlier branch's).
        let last_after_decision = self.last.clone();
        let mut written: Vec<Vec<Branch>> = vec![Vec::new(); self.n];
        for (k, br) in branches.iter().enumerate() {
            self.know = after_decision.clone();
            self.last.clone_from(&last_after_decision);
            for &p in &parts {
                self.stacks[p].push(Vec::new());
            }
            for &ch in &channels {
                let m = Message {
                    channel: ch,
                    kind: Kind::Decision,
                    value: k,
                    about: div,
                };
                self.push(d, Block::Tell(m));
            }
            let end = self.blocks(
                &br.body,
                vec![(d, decided, div, Kind::Passed(Construct::Decided))],
            );
            if matches!(br.end, BranchEnd::Repeat(_))
                && let Some(l) = self.loops.last().cloned()
            {
                // The next round's first step comes after this branch.
                for p in l {
                    self.acquire(p, &end);
                }
            }
            for &p in &parts {
                let body = self.stacks[p].pop().unwrap_or_default();
                written[p].push(Branch {
                    transition: br.transition,
                    body,
                    end: br.end,
                });
            }
        }
        self.know = after_decision;
        let mut out = Vec::new();
        for &p in &parts {
            let branches = std::mem::take(&mut written[p]);
            let block = if p == d {
                Block::Choice {
                    divergence: div,
                    convergence,
                    branches,
                }
            } else {
                let k = followers.iter().position(|&f| f == p).unwrap_or(0);
                Block::Follow {
                    divergence: div,
                    heard: Message {
                        channel: channels[k],
                        kind: Kind::Decision,
                        value: 0,
                        about: div,
                    },
                    branches,
                }
            };
            self.push(p, block);
            let passed = Kind::Passed(Construct::Selection);
            let t = self.tick(p, div, passed);
            out.push((p, t, div, passed));
        }
        out
    }
}

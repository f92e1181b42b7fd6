//! Exhaustive explicit-state model check of the cell handshake protocol as the compiler writes
//! it (src/emit/handshake/mod.rs: `Hand::init`, `tell`, `hear`, `finish`: the barrier at each
//! program's start, then Tell/Hear on strobe/ack wires), std only. Every interleaving of the
//! programs' atomic actions and of the environment's events is explored breadth-first (so each
//! printed counter-example is a shortest one); `cargo test --release --test protocol_model --
//! --nocapture` prints every configuration's figures and traces.
//!
//! # Model
//!
//! - Wires are levels driven by one program: per ordered pair of partners `R_XY` (run) and
//!   `B_XY` (ready); per channel X->Y a strobe `S_XY` (X drives) and an ack `K_XY` (Y drives).
//!   All start at 0 and keep their level when a program stops, ends or restarts.
//! - A program is its code, one atomic action per wire write and per read. A `WAIT`/`IF` reads
//!   all its wires at once (a snapshot: false = no move, true = next action); a wait and the
//!   `IF` after it are two reads, with any other moves in between. The written protocol:
//!   1 R := 0 to every partner; 2 B := 0 to every partner, then the strobes it drives, then the
//!   acks; 3 wait until every partner shows R_YX == 0; 4 B := 1; 5 wait until every partner
//!   shows B_YX == 1; 6 R := 1; 7 wait until every partner shows R_YX == 1 or some partner shows
//!   R_YX == 0 AND B_YX == 0, then (second read) STOP if some partner shows R_YX == 0 AND
//!   B_YX == 0; 8 B := 0. A Tell #j waits until K == tx OR R_YX == 0, then (second read) STOPs
//!   if R_YX == 0, else S := NOT tx; a Hear #j (rx := NOT rx) waits until S == rx OR
//!   R_YX == 0, then STOPs if R_YX == 0, else K := rx. At its end a program waits, per channel
//!   it tells on, until K == tx OR R_YX == 0, and goes on without stopping. STOP: the program
//!   halts until the operator restarts it. Toggles are local and reset with the restart;
//!   partners in index order.
//! - Environment: an ended program is restarted for its next cycle (at most `cycles` cycles per
//!   program); a fault restarts any program that is neither ended nor stopped, at any point
//!   (inside the barrier, right after another restart; at most `faults` in all); the operator
//!   restarts a stopped program at any later time (unbounded: sessions and runs are renamed by
//!   first appearance, so the state space stays finite).
//! - Ghosts: each restart begins a new *session*; each wire level is tagged with the session
//!   that wrote it, what it was (initial level, reset, Tell #j, ack of Hear #j) and that
//!   session's *cell run*; between a Tell/Hear wait and its second read, the program keeps the
//!   tag of the K/S level its wait read (or that it passed on R == 0 alone). Cell runs: every
//!   session begins in a run of its own; when a program goes on past a partner's R = 1
//!   (action 7, a Tell's or Hear's second read, an end wait that passes on the ack) its run and
//!   the run of the session that wrote that R become one (union). Per run: the programs with a
//!   session in it and how often each step ran (capped at 3).
//!
//! # Properties
//!
//! - P1: a Hear #j on Y->X goes on (its second read sees R_YX = 1) only on an S level, read by
//!   its wait, that the session driving R_YX wrote with its Tell #j; a Tell #j only on a K level
//!   of that session: its reset (j = 0) or its ack of #j-1; an end wait that passes on the ack
//!   while R = 1, only on the ack of the last message. (A wait that passed on R_YX == 0 alone
//!   and is followed by R_YX = 1 at the second read took no message: a violation.)
//! - P2: every such pass is on a level written in the waiter's own cell run, and in no cell run
//!   does a step run more often than a step of another program that precedes it in the chart
//!   (a before b: a before a Tell whose Hear is before b; closed transitively).
//! - P3: when a program leaves the barrier (its last action 8), every partner is at its start
//!   (actions 1-8 of its current session, or just restarted) or its current session left the
//!   barrier after this session began, in the same cell run. Also counted, not asserted:
//!   "two rounds in one run" (a run with two sessions of one program).
//! - P4: once a partner's new session wrote R_YX := 0 while X was past action 7, no later Tell or
//!   Hear of X on Y goes on (the end wait is exempt: it goes on by design).
//! - P5: (a) no reachable state where every program waits forever (none ended or stopped);
//!   (b) from the ghost-free image of every reachable state, with no more faults and the
//!   operator restarting ended and stopped programs at any time (no cycle bound), a state where
//!   every program has completed a whole cycle (left the barrier, then END) is reachable
//!   (backward reachability over that graph). Also computed, beyond P5: whether every path
//!   completes (AF), and whether a path that never completes can avoid STOPs.
//!
//! # Bodies and bounds
//!
//! One channel X: [a, Tell XY], Y: [Hear XY, b]; both directions X: [a, Tell XY, Hear YX, c],
//! Y: [Hear XY, b, Tell YX]; two messages X: [a, Tell, c, Tell], Y: [Hear, b, Hear, d]; chain
//! X: [a, Tell XY], Y: [Hear XY, b, Tell YZ], Z: [Hear YZ, c]; triangle (all three partners)
//! X: [a, Tell XY, Tell XZ], Y: [Hear XY, b, Tell YZ], Z: [Hear XZ, Hear YZ, c]. Default tests
//! (`cargo test` runs them in debug): the two-program bodies with 3 cycles and 2 faults, the
//! chain with 2 cycles and 1 fault, the triangle with 1 cycle and 1 fault. Not modelled: more
//! than three programs (so no four-program cycle, the square W-X-Y-Z-W), decision data bits,
//! robot motion (waits for the robot to stand).
//!
//! # Results (states; release times; `cargo test --release --test protocol_model -- --nocapture`)
//!
//! The written protocol (`protocol_*`): P1-P5 hold on every body at the default bounds: one
//! channel 9,180 states, both directions 13,017, two messages 10,754, chain 58,797 (0.6 s),
//! triangle 64,155 (0.8 s); every recovery that never completes has a STOP (and the operator's
//! restart) in each round. Bigger bounds (`bigger_bounds`, ignored by default, 22 s): the
//! two-program bodies with 4 cycles and 3 faults 28,566 / 42,629 / 33,341; chain 3 cycles
//! 1 fault 133,393, 3 cycles 2 faults 772,249, 4 cycles 1 fault 251,248; triangle 2 cycles
//! 1 fault 230,118, 3 cycles 1 fault 549,127, 2 cycles 2 faults 1,562,134: all hold. "Two
//! rounds in one run" is seen on the triangle only (Z passes action 7 on the R_XZ = 1 of X's
//! stopped session before X's new session has dropped it); P1-P4 hold, so no message of an old
//! session is taken. `protocol_recovery_can_loop_only_through_stops` (one channel, 1 cycle,
//! 2 faults, 1,517 states): P5 holds; some recoveries can go round without completing (two
//! programs pass each other's barrier out of phase, each STOPs in turn), every such loop through
//! a STOP and an operator restart.
//!
//! Why action 7 is as it is, two earlier designs, each kept as a test:
//!
//! - First design (`first_design_triangle_deadlocks`; action 7 waits until R_YX == 1 OR
//!   B_YX == 0 for every partner, no stop): on the triangle with 1 cycle and 1 fault every
//!   program waits forever after 9,055 states (36 events: X passes action 5 and raises R;
//!   Z restarts; X waits at 7 for Y's go, Y at 5 for Z's ready, Z at 3 for R_XZ = 0; nobody
//!   STOPs, so no operator is called).
//! - Second design (`second_design_takes_a_message_never_sent`; action 7's second read STOPs
//!   only if some partner shows R_YX == 0 AND B_YX == 0): one channel, P1 and P2 fail after
//!   1,253 states (25 events: X restarts inside its barrier; Y's action-7 wait passes on X's
//!   R = 0, B = 0; X raises B before Y's second read, so Y goes into its cycle; Y's Hear wait
//!   passes on X's R = 0; X raises R; Y's second read sees R = 1 and takes a message X never
//!   sent). Reading "STOP unless every partner is running" closes it: a partner the wait passed
//!   on cannot raise R again before this program's R drops (its action 3 waits for that).
//! - `retry_instead_of_stop_can_loop_by_itself` (the second read sends the program back to
//!   action 1 instead of STOP): 15,365 states; the programs can go round forever without
//!   completing and without a STOP (356 states).
//!
//! Mutations of the written protocol (two-program bodies and chain at the default bounds;
//! M1b, M2, M3 stop at 20,000 states), each found on every body: M1 no barrier (actions 3-8
//! removed): P3 (a program leaves its start while the partner is in an older cycle) and P5;
//! M1b actions 3-5, 7, 8 removed but R := 1 kept: P1-P4; M2 Hear without the R guard: P1 and
//! P4 (a message of the teller's previous session) and P5 (all blocked); M3 action 2 before
//! action 1: P1 (a Tell takes the restarted hearer's reset ack).
//!
//! Times of the default tests on 2 cores: release 1.6 s; debug (`cargo test --test
//! protocol_model`, as CI runs it) about 20 s.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, VecDeque};
use std::fmt::Write as _;
use std::hash::{BuildHasherDefault, Hasher};
use std::time::Instant;

// ---------------------------------------------------------------------------------------------
// Sizes and encodings
// ---------------------------------------------------------------------------------------------

const MAXP: usize = 3; // programs
const MAXW: usize = 6; // ordered partner pairs (R and B wires)
const MAXC: usize = 4; // channels (S and K wires)
const MAXS: usize = 6; // step names
const MAXRUN: usize = 16; // cell runs named in a state (sessions' and wire tags')
const NONE: u8 = u8::MAX; // no session / no run / nobody
const FRESH: u8 = 250; // a new session's id until the state is canonicalised
const STOPPED: u8 = 0x80; // flag on the pc of a stopped program (the rest: where it stopped)
/// Step counts per cell run saturate here (a correct run has each step at most once; only runs
/// that already hold two sessions of one program, a P3 violation, count further).
const COUNT_CAP: u8 = 3;

// Wire tag kinds: who wrote the level and with what.
const K_INIT: u8 = 0; // the level the cell started with (nobody wrote it)
const K_RESET: u8 = 1; // a program's reset at its start (action 2)
const K_MSG: u8 = 2; // + j: the Tell #j (on S) or the acknowledgement of Hear #j (on K)
/// Kind of a `held` tag: the wait passed on R == 0 with the level not yet equal to the toggle.
const K_NOMATCH: u8 = 0xFE;

// ---------------------------------------------------------------------------------------------
// The system: bodies, the protocol's code, variants
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug)]
enum Item {
    Step(&'static str),
    Tell(usize),
    Hear(usize),
}

struct Spec {
    name: &'static str,
    progs: Vec<&'static str>,
    /// (teller, hearer)
    chans: Vec<(usize, usize)>,
    bodies: Vec<Vec<Item>>,
}

/// The protocol the compiler writes, a variant of it (the second design, retry), its
/// first design, or one mutation of the written one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Variant {
    /// Actions 1-8 as the compiler writes them: action 7 waits until every partner has
    /// R_YX == 1 or some partner shows R_YX == 0 AND B_YX == 0, then (a second read) STOPs
    /// unless every partner shows R_YX == 1.
    Written,
    /// The second design: as written, but the second read of action 7 STOPs only if some
    /// partner shows R_YX == 0 AND B_YX == 0 (a restarted partner that raised B between the
    /// two reads is missed).
    StopIfRestarted,
    /// The first design: action 7 waits until R_YX == 1 OR B_YX == 0 for every partner, no stop.
    FirstDesign,
    /// Written, but a restarted partner at action 7 sends the program back to action 1
    /// instead of STOP.
    Retry,
    /// M1: actions 3-8 removed (so R is never set to 1 either).
    NoBarrier,
    /// M1b: actions 3-5, 7, 8 removed, action 6 (R := 1) kept right after the resets.
    NoBarrierKeepGo,
    /// M2: a Hear waits `until S == rx`, without the R guard and without STOP.
    HearNoGuard,
    /// M3: action 2 (resets of B, S, K) before action 1 (R := 0).
    ResetBeforeR,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    SetR {
        w: usize,
        v: bool,
    },
    SetB {
        w: usize,
        v: bool,
    },
    ResetS(usize),
    ResetK(usize),
    /// 3: R_YX == 0 for every partner
    WaitR0,
    /// 5: B_YX == 1 for every partner
    WaitB1,
    /// 7 as written: every partner R_YX == 1, or some partner R_YX == 0 AND B_YX == 0
    WaitGo,
    /// 7 of the second design, second read: some partner R_YX == 0 AND B_YX == 0 -> STOP (or, `retry`,
    /// back to action 1)
    StopIfRestarted {
        retry: bool,
    },
    /// 7 as written, second read: not every partner R_YX == 1 -> STOP
    StopUnlessRunning,
    /// 7 of the first design: R_YX == 1 or B_YX == 0 for every partner
    WaitGoFirst,
    Step(usize),
    /// Tell #j: wait until K == tx OR R == 0 (the K level read is kept for the check)
    TellWait {
        c: usize,
        j: u8,
    },
    /// Tell #j, second read: R == 0 -> STOP, else the message is sent
    TellCheck {
        c: usize,
        j: u8,
    },
    TellSet {
        c: usize,
        j: u8,
    },
    /// Hear #j: wait until S == rx OR R == 0 (`guard` false, M2: until S == rx, no check)
    HearWait {
        c: usize,
        j: u8,
        guard: bool,
    },
    /// Hear #j, second read: R == 0 -> STOP, else the message is taken
    HearCheck {
        c: usize,
        j: u8,
    },
    HearSet {
        c: usize,
        j: u8,
    },
    EndWait {
        c: usize,
        last: u8,
    },
    End,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// With ghosts, faults and property checks.
    Main,
    /// Ghost-free, no faults, unbounded restarts of ended and stopped programs (P5).
    Recovery,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Ev {
    /// The program's next action.
    Act,
    /// A fault restart.
    Fault,
    /// The operator restarts a stopped program.
    Operator,
    /// An ended program is restarted for its next cycle.
    Next,
}

#[derive(Clone, Copy, Debug)]
struct Label {
    ev: Ev,
    p: u8,
}

/// A `held` tag or an R tag that stands for "no level of a partner's session": the wait passed
/// on R == 0 alone, or (M2) R read 0 when the Hear passed.
const NOMATCH: Tag = Tag {
    sess: NONE,
    kind: K_NOMATCH,
    run: NONE,
};

/// Violations found on one transition: the property and what happened.
type Viols = Vec<(Prop, String)>;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Prop {
    P1,
    P2,
    P3,
    P4,
    /// Not one of P1-P5: two sessions of one program ended up in one cell run (a session's
    /// stale R = 1 linked two rounds). Reported, not asserted.
    Bridge,
}

// ---------------------------------------------------------------------------------------------
// State
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct Tag {
    /// Session of the wire's driver that wrote the level (NONE: initial level).
    sess: u8,
    /// K_INIT, K_RESET or K_MSG + j.
    kind: u8,
    /// Cell run of the writer's session (relabelled when runs merge; NONE: initial level).
    run: u8,
}

const TAG0: Tag = Tag {
    sess: NONE,
    kind: K_INIT,
    run: NONE,
};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct Prog {
    /// Index of the next action (| STOPPED: it stopped there); the End op's index = ended.
    pc: u8,
    /// Restarts after END so far (ghost bound of the exploration).
    cycles: u8,
    tx: u8,
    rx: u8,
    /// Ghost: current session (always 0 once canonicalised; FRESH right after a restart).
    sess: u8,
    /// Ghost: bit q set when partner q's current session left the barrier after this session
    /// began (so the two are in the same cell run).
    met: u8,
    /// Ghost: the cell run of this session (its own one from its start on, merged with a
    /// partner's when it passes a wait on the partner's R = 1).
    run: u8,
    /// Ghost (P4): partner bit set when the partner's new session wrote R := 0 while this
    /// session was inside its cycle.
    seen: u8,
    /// Ghost (P1, P2): between a Tell/Hear wait and its check, the tag of the K/S level the
    /// wait read (kind K_NOMATCH: it passed on R == 0 alone); TAG0 elsewhere.
    held: Tag,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
struct Run {
    members: u8,
    counts: [u8; MAXS],
}

#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct State {
    p: [Prog; MAXP],
    /// R wires: level, writer (kind unused).
    r: [(bool, Tag); MAXW],
    b: [bool; MAXW],
    s: [(bool, Tag); MAXC],
    k: [(bool, Tag); MAXC],
    /// Ghost (P2, P3): per cell run, the programs with a session in it and how often each step
    /// ran in it.
    runs: [Run; MAXRUN],
    faults: u8,
    /// Recovery mode only: bits 0..3 = left the barrier since recovery began (this session),
    /// bits 4..7 = completed a whole cycle since recovery began.
    rec: u8,
}

fn bit(m: u8, i: usize) -> bool {
    m >> i & 1 == 1
}

// ---------------------------------------------------------------------------------------------
// The compiled model
// ---------------------------------------------------------------------------------------------

struct Model {
    spec_name: &'static str,
    variant: Variant,
    n: usize,
    names: Vec<&'static str>,
    chans: Vec<(usize, usize)>,
    /// (from, to) of each R/B wire pair.
    pairs: Vec<(usize, usize)>,
    pair: [[u8; MAXP]; MAXP],
    partners: Vec<Vec<usize>>,
    ops: Vec<Vec<Op>>,
    /// Index of the action after which the program has left the barrier.
    leave_op: Vec<usize>,
    /// First pc of "inside the cycle" for P4 (after action 7 passed).
    cycle_from: Vec<usize>,
    end_op: Vec<usize>,
    steps: Vec<&'static str>,
    /// (a, b): step b must never run more often in a cell run than step a (cross-program,
    /// transitively closed).
    deps: Vec<(usize, usize)>,
    cycles: u8,
    max_faults: u8,
}

impl Model {
    #[allow(clippy::needless_range_loop)] // tables indexed by program and step
    fn new(spec: &Spec, variant: Variant, cycles: u8, max_faults: u8) -> Model {
        let n = spec.progs.len();
        assert!(n <= MAXP && spec.chans.len() <= MAXC);
        let mut pair = [[NONE; MAXP]; MAXP];
        let mut pairs = Vec::new();
        let mut partners = vec![Vec::new(); n];
        for x in 0..n {
            for y in 0..n {
                if x != y
                    && spec
                        .chans
                        .iter()
                        .any(|&(a, b)| (a, b) == (x, y) || (a, b) == (y, x))
                {
                    pair[x][y] = pairs.len() as u8;
                    pairs.push((x, y));
                    partners[x].push(y);
                }
            }
        }
        assert!(pairs.len() <= MAXW);
        let mut steps = Vec::new();
        for body in &spec.bodies {
            for it in body {
                if let Item::Step(s) = it {
                    assert!(!steps.contains(s), "step names are unique");
                    steps.push(*s);
                }
            }
        }
        assert!(steps.len() <= MAXS);
        let step_id = |s: &str| steps.iter().position(|t| *t == s).unwrap();
        let mut ops = Vec::new();
        let mut leave_op = Vec::new();
        let mut cycle_from = Vec::new();
        let mut end_op = Vec::new();
        for x in 0..n {
            let mut o = Vec::new();
            let w = |y: usize| pair[x][y] as usize;
            let act1: Vec<Op> = partners[x]
                .iter()
                .map(|&y| Op::SetR { w: w(y), v: false })
                .collect();
            let mut act2: Vec<Op> = partners[x]
                .iter()
                .map(|&y| Op::SetB { w: w(y), v: false })
                .collect();
            for (c, &(t, _)) in spec.chans.iter().enumerate() {
                if t == x {
                    act2.push(Op::ResetS(c));
                }
            }
            for (c, &(_, h)) in spec.chans.iter().enumerate() {
                if h == x {
                    act2.push(Op::ResetK(c));
                }
            }
            if variant == Variant::ResetBeforeR {
                o.extend(act2);
                o.extend(act1);
            } else {
                o.extend(act1);
                o.extend(act2);
            }
            match variant {
                Variant::NoBarrier => {}
                Variant::NoBarrierKeepGo => {
                    o.extend(partners[x].iter().map(|&y| Op::SetR { w: w(y), v: true }))
                }
                _ => {
                    o.push(Op::WaitR0);
                    o.extend(partners[x].iter().map(|&y| Op::SetB { w: w(y), v: true }));
                    o.push(Op::WaitB1);
                    o.extend(partners[x].iter().map(|&y| Op::SetR { w: w(y), v: true }));
                    // Action 7. As written (`Hand::init`): the wait, then `stop_if(restarted)`.
                    match variant {
                        Variant::FirstDesign => o.push(Op::WaitGoFirst),
                        Variant::StopIfRestarted | Variant::Retry => o.extend([
                            Op::WaitGo,
                            Op::StopIfRestarted {
                                retry: variant == Variant::Retry,
                            },
                        ]),
                        _ => o.extend([Op::WaitGo, Op::StopUnlessRunning]),
                    }
                }
            }
            // Action 8 (or the end of a barrier without it): the program is in its cycle.
            cycle_from.push(o.len());
            if !matches!(variant, Variant::NoBarrier | Variant::NoBarrierKeepGo) {
                o.extend(partners[x].iter().map(|&y| Op::SetB { w: w(y), v: false }));
            }
            leave_op.push(o.len() - 1);
            let mut count = vec![0u8; spec.chans.len()];
            for it in &spec.bodies[x] {
                match *it {
                    Item::Step(s) => o.push(Op::Step(step_id(s))),
                    Item::Tell(c) => {
                        assert_eq!(spec.chans[c].0, x);
                        let j = count[c];
                        o.extend([Op::TellWait { c, j }, Op::TellCheck { c, j }]);
                        o.push(Op::TellSet { c, j });
                        count[c] += 1;
                    }
                    Item::Hear(c) => {
                        assert_eq!(spec.chans[c].1, x);
                        let j = count[c];
                        if variant == Variant::HearNoGuard {
                            o.push(Op::HearWait { c, j, guard: false });
                        } else {
                            o.push(Op::HearWait { c, j, guard: true });
                            o.push(Op::HearCheck { c, j });
                        }
                        o.push(Op::HearSet { c, j });
                        count[c] += 1;
                    }
                }
            }
            for (c, &(t, _)) in spec.chans.iter().enumerate() {
                if t == x {
                    assert!(count[c] > 0);
                    o.push(Op::EndWait {
                        c,
                        last: count[c] - 1,
                    });
                }
            }
            end_op.push(o.len());
            o.push(Op::End);
            assert!(o.len() < STOPPED as usize);
            ops.push(o);
        }
        // Chart order between steps of different programs, closed transitively.
        let ns = steps.len();
        let mut before = vec![vec![false; ns]; ns];
        for body in &spec.bodies {
            let ids: Vec<usize> = body
                .iter()
                .filter_map(|it| match it {
                    Item::Step(s) => Some(step_id(s)),
                    _ => None,
                })
                .collect();
            for i in 0..ids.len() {
                for k in i + 1..ids.len() {
                    before[ids[i]][ids[k]] = true;
                }
            }
        }
        for (c, _) in spec.chans.iter().enumerate() {
            let (t, h) = spec.chans[c];
            let mut j = 0;
            loop {
                let pos_t = nth(
                    &spec.bodies[t],
                    |it| matches!(it, Item::Tell(d) if *d == c),
                    j,
                );
                let pos_h = nth(
                    &spec.bodies[h],
                    |it| matches!(it, Item::Hear(d) if *d == c),
                    j,
                );
                let (Some(pt), Some(ph)) = (pos_t, pos_h) else {
                    assert_eq!(pos_t.is_some(), pos_h.is_some(), "a Tell for every Hear");
                    break;
                };
                for a in spec.bodies[t][..pt].iter() {
                    for b in spec.bodies[h][ph..].iter() {
                        if let (Item::Step(a), Item::Step(b)) = (a, b) {
                            before[step_id(a)][step_id(b)] = true;
                        }
                    }
                }
                j += 1;
            }
        }
        for m in 0..ns {
            for a in 0..ns {
                for b in 0..ns {
                    if before[a][m] && before[m][b] {
                        before[a][b] = true;
                    }
                }
            }
        }
        let owner = |s: usize| {
            (0..n)
                .find(|&x| {
                    spec.bodies[x]
                        .iter()
                        .any(|it| matches!(it, Item::Step(t) if *t == steps[s]))
                })
                .unwrap()
        };
        let mut deps = Vec::new();
        for a in 0..ns {
            for b in 0..ns {
                if before[a][b] && owner(a) != owner(b) {
                    deps.push((a, b));
                }
            }
        }
        Model {
            spec_name: spec.name,
            variant,
            n,
            names: spec.progs.clone(),
            chans: spec.chans.clone(),
            pairs,
            pair,
            partners,
            ops,
            leave_op,
            cycle_from,
            end_op,
            steps,
            deps,
            cycles,
            max_faults,
        }
    }

    fn w(&self, from: usize, to: usize) -> usize {
        self.pair[from][to] as usize
    }

    fn init(&self) -> State {
        let prog = Prog {
            pc: 0,
            cycles: 0,
            tx: 0,
            rx: 0,
            sess: 0,
            met: 0,
            run: NONE,
            seen: 0,
            held: TAG0,
        };
        let mut s = State {
            p: [prog; MAXP],
            r: [(false, TAG0); MAXW],
            b: [false; MAXW],
            s: [(false, TAG0); MAXC],
            k: [(false, TAG0); MAXC],
            runs: [Run::default(); MAXRUN],
            faults: 0,
            rec: 0,
        };
        for p in 0..self.n {
            s.p[p].run = p as u8;
            s.runs[p].members = 1 << p;
        }
        s
    }

    fn ended(&self, s: &State, p: usize) -> bool {
        s.p[p].pc as usize == self.end_op[p]
    }

    fn stopped(&self, s: &State, p: usize) -> bool {
        s.p[p].pc & STOPPED != 0
    }

    /// Inside the actions 1-8 of its current session (not yet left the barrier; it may have
    /// stopped there, at action 7).
    fn at_start(&self, s: &State, p: usize) -> bool {
        (s.p[p].pc & !STOPPED) as usize <= self.leave_op[p]
    }

    /// Passed action 7 and not yet ended or stopped.
    fn in_cycle(&self, s: &State, p: usize) -> bool {
        let pc = s.p[p].pc;
        pc & STOPPED == 0 && pc as usize >= self.cycle_from[p] && (pc as usize) < self.end_op[p]
    }

    fn chan_name(&self, c: usize) -> String {
        let (t, h) = self.chans[c];
        format!("{}{}", self.names[t], self.names[h])
    }

    fn wire_name(&self, w: usize) -> String {
        let (a, b) = self.pairs[w];
        format!("{}{}", self.names[a], self.names[b])
    }

    /// How a wire tag reads to a person (sessions relative to the writer's current one).
    fn tag_text(&self, t: Tag, writer: usize, s: &State, what_msg: &str) -> String {
        if t.kind == K_INIT {
            return "the cell's initial level".into();
        }
        if t.kind == K_NOMATCH {
            return "nobody (the wait passed on R == 0 before the level came)".into();
        }
        let who = if t.sess == s.p[writer].sess {
            format!("{}'s current session", self.names[writer])
        } else {
            format!("an earlier session of {}", self.names[writer])
        };
        if t.kind == K_RESET {
            format!("{who} (its reset)")
        } else {
            format!("{who} ({what_msg} #{})", t.kind - K_MSG)
        }
    }

    fn restart(&self, s: &mut State, p: usize, ev: Ev) {
        let old = s.p[p];
        s.p[p] = Prog {
            pc: 0,
            cycles: old.cycles + (ev == Ev::Next) as u8,
            tx: 0,
            rx: 0,
            sess: FRESH,
            met: 0,
            run: NONE,
            seen: 0,
            held: TAG0,
        };
        // The new session begins a cell run of its own.
        let refs = s.p[..self.n]
            .iter()
            .flat_map(|x| [x.run, x.held.run])
            .chain(s.r.iter().chain(&s.s).chain(&s.k).map(|w| w.1.run))
            .filter(|&r| r != NONE)
            .max();
        let id = refs.map_or(0, |r| r as usize + 1);
        assert!(id < MAXRUN, "MAXRUN too small");
        s.runs[id] = Run {
            members: 1 << p,
            counts: [0; MAXS],
        };
        s.p[p].run = id as u8;
        // No partner's session has left the barrier after this new session began.
        for q in 0..self.n {
            s.p[q].met &= !(1 << p);
        }
        if ev == Ev::Fault {
            s.faults += 1;
        }
        s.rec &= !(1 << p);
    }

    /// Executes program `p`'s next action, if enabled. Violations found go into `viol`.
    fn act(&self, st: &State, p: usize, mode: Mode, viol: &mut Viols) -> Option<State> {
        let main = mode == Mode::Main;
        let me = st.p[p];
        let pc = me.pc as usize;
        let mut s = st.clone();
        let name = self.names[p];
        match self.ops[p][pc] {
            Op::SetR { w, v } => {
                s.r[w] = (
                    v,
                    Tag {
                        sess: me.sess,
                        kind: K_MSG,
                        run: me.run,
                    },
                );
                let q = self.pairs[w].1;
                if !v && main && self.in_cycle(st, q) {
                    s.p[q].seen |= 1 << p;
                }
            }
            Op::SetB { w, v } => s.b[w] = v,
            Op::ResetS(c) => {
                s.s[c] = (
                    false,
                    Tag {
                        sess: me.sess,
                        kind: K_RESET,
                        run: NONE,
                    },
                )
            }
            Op::ResetK(c) => {
                s.k[c] = (
                    false,
                    Tag {
                        sess: me.sess,
                        kind: K_RESET,
                        run: NONE,
                    },
                )
            }
            Op::WaitR0 => {
                if self.partners[p].iter().any(|&q| st.r[self.w(q, p)].0) {
                    return None;
                }
            }
            Op::WaitB1 => {
                if self.partners[p].iter().any(|&q| !st.b[self.w(q, p)]) {
                    return None;
                }
            }
            Op::WaitGo => {
                let running = self.partners[p].iter().all(|&q| st.r[self.w(q, p)].0);
                if !running && !self.restarted_partner(st, p) {
                    return None;
                }
                if main {
                    self.union_with_running(&mut s, st, p, viol);
                }
            }
            Op::StopIfRestarted { retry } => {
                if self.restarted_partner(st, p) {
                    if retry {
                        self.restart(&mut s, p, Ev::Act);
                    } else {
                        s.p[p].pc |= STOPPED;
                    }
                    return Some(s);
                }
            }
            Op::StopUnlessRunning => {
                if !self.partners[p].iter().all(|&q| st.r[self.w(q, p)].0) {
                    s.p[p].pc |= STOPPED;
                    return Some(s);
                }
            }
            Op::WaitGoFirst => {
                if self.partners[p].iter().any(|&q| {
                    let w = self.w(q, p);
                    !st.r[w].0 && st.b[w]
                }) {
                    return None;
                }
                if main {
                    self.union_with_running(&mut s, st, p, viol);
                }
            }
            Op::Step(id) => {
                if main {
                    let c = &mut s.runs[me.run as usize].counts;
                    c[id] = (c[id] + 1).min(COUNT_CAP);
                    for &(a, b) in &self.deps {
                        if b == id && c[b] > c[a] {
                            viol.push((
                                Prop::P2,
                                format!(
                                    "step {} ran {} time(s) in this cell run, step {} before it in the chart only {}",
                                    self.steps[b], c[b], self.steps[a], c[a]
                                ),
                            ));
                        }
                    }
                }
            }
            Op::TellWait { c, .. } => {
                let q = self.chans[c].1;
                let k = st.k[c];
                let matched = k.0 == bit(me.tx, c);
                if !matched && st.r[self.w(q, p)].0 {
                    return None;
                }
                if main {
                    s.p[p].held = if matched { k.1 } else { NOMATCH };
                }
            }
            Op::TellCheck { c, j } => {
                let q = self.chans[c].1;
                let r = st.r[self.w(q, p)];
                s.p[p].held = TAG0;
                if !r.0 {
                    s.p[p].pc |= STOPPED;
                    return Some(s);
                }
                if main {
                    let want = if j == 0 { K_RESET } else { K_MSG + j - 1 };
                    let what = |k: Tag| {
                        format!(
                            "{name}'s Tell {}#{j} passed on K_{} written by {}",
                            self.chan_name(c),
                            self.chan_name(c),
                            self.tag_text(k, q, st, "ack of Hear")
                        )
                    };
                    self.pass_checks(&mut s, st, p, q, r.1, me.held, want, j > 0, what, viol);
                }
            }
            Op::TellSet { c, j } => {
                let tx = !bit(me.tx, c);
                s.p[p].tx ^= 1 << c;
                s.s[c] = (
                    tx,
                    Tag {
                        sess: me.sess,
                        kind: K_MSG + j,
                        run: me.run,
                    },
                );
            }
            Op::HearWait { c, j, guard } => {
                let q = self.chans[c].0;
                let r = st.r[self.w(q, p)];
                let sv = st.s[c];
                let matched = sv.0 != bit(me.rx, c);
                if !matched && (!guard || r.0) {
                    return None;
                }
                s.p[p].rx ^= 1 << c;
                let held = if matched { sv.1 } else { NOMATCH };
                if main && guard {
                    s.p[p].held = held;
                } else if main {
                    // M2: taken right here, whatever R reads.
                    let what = |t: Tag| {
                        format!(
                            "{name}'s Hear {}#{j} passed on S_{} written by {}",
                            self.chan_name(c),
                            self.chan_name(c),
                            self.tag_text(t, q, st, "Tell")
                        )
                    };
                    let r = if r.0 { r.1 } else { NOMATCH };
                    self.pass_checks(&mut s, st, p, q, r, held, K_MSG + j, true, what, viol);
                }
            }
            Op::HearCheck { c, j } => {
                let q = self.chans[c].0;
                let r = st.r[self.w(q, p)];
                s.p[p].held = TAG0;
                if !r.0 {
                    s.p[p].pc |= STOPPED;
                    return Some(s);
                }
                if main {
                    let what = |t: Tag| {
                        format!(
                            "{name}'s Hear {}#{j} passed on S_{} written by {}",
                            self.chan_name(c),
                            self.chan_name(c),
                            self.tag_text(t, q, st, "Tell")
                        )
                    };
                    self.pass_checks(&mut s, st, p, q, r.1, me.held, K_MSG + j, true, what, viol);
                }
            }
            Op::HearSet { c, j } => {
                s.k[c] = (
                    bit(me.rx, c),
                    Tag {
                        sess: me.sess,
                        kind: K_MSG + j,
                        run: me.run,
                    },
                );
            }
            Op::EndWait { c, last } => {
                let q = self.chans[c].1;
                let r = st.r[self.w(q, p)];
                let k = st.k[c];
                let tx = bit(me.tx, c);
                if k.0 != tx && r.0 {
                    return None;
                }
                if main && r.0 {
                    // Passed on the acknowledgement (R == 1): it must be the last one's.
                    self.union(&mut s, me.run, r.1.run, viol);
                    let run = s.p[p].run;
                    let what = format!(
                        "{name}'s end wait on {} passed on K_{}={} written by {}",
                        self.chan_name(c),
                        self.chan_name(c),
                        k.0 as u8,
                        self.tag_text(k.1, q, st, "ack of Hear")
                    );
                    if !(k.1.sess == r.1.sess && k.1.kind == K_MSG + last) {
                        viol.push((Prop::P1, what.clone()));
                    }
                    if k.1.run != run {
                        viol.push((
                            Prop::P2,
                            format!("{what}, in another cell run than {name}'s"),
                        ));
                    }
                }
            }
            Op::End => return None,
        }
        s.p[p].pc += 1;
        if pc == self.leave_op[p] {
            self.leave(&mut s, p, mode, viol);
        }
        if mode == Mode::Recovery && s.p[p].pc as usize == self.end_op[p] && bit(s.rec, p) {
            s.rec |= 1 << (4 + p);
        }
        Some(s)
    }

    /// Some partner shows R_YX == 0 AND B_YX == 0 (it was restarted).
    fn restarted_partner(&self, st: &State, p: usize) -> bool {
        self.partners[p].iter().any(|&q| {
            let w = self.w(q, p);
            !st.r[w].0 && !st.b[w]
        })
    }

    /// Action 7 passed: `p`'s cell run becomes one with that of every R = 1 it read.
    fn union_with_running(&self, s: &mut State, st: &State, p: usize, viol: &mut Viols) {
        for &q in &self.partners[p] {
            let r = st.r[self.w(q, p)];
            if r.0 {
                let mine = s.p[p].run;
                self.union(s, mine, r.1.run, viol);
            }
        }
    }

    /// `p` takes a Tell's ack or a Hear's message from partner `q`: `level` is the tag of the K
    /// or S level its wait read, `r` that of R_qp read afterwards (NOMATCH: R read 0); `want`
    /// the kind the level must have. P1: written by the session that drives R, with `want`;
    /// P2 (if `same_run`): in `p`'s cell run; P4: `q` did not restart during `p`'s cycle.
    #[allow(clippy::too_many_arguments)]
    fn pass_checks(
        &self,
        s: &mut State,
        st: &State,
        p: usize,
        q: usize,
        r: Tag,
        level: Tag,
        want: u8,
        same_run: bool,
        what: impl Fn(Tag) -> String,
        viol: &mut Viols,
    ) {
        let me = st.p[p];
        if r != NOMATCH {
            self.union(s, me.run, r.run, viol);
        }
        let run = s.p[p].run;
        let text = || what(level);
        if r == NOMATCH || level == NOMATCH || level.sess != r.sess || level.kind != want {
            viol.push((Prop::P1, text()));
        }
        if same_run && level.run != run {
            viol.push((
                Prop::P2,
                format!("{}, in another cell run than {}'s", text(), self.names[p]),
            ));
        }
        if bit(me.seen, q) {
            viol.push((
                Prop::P4,
                format!(
                    "{} although {} restarted during this cycle",
                    text(),
                    self.names[q]
                ),
            ));
        }
    }

    /// Program `p` has just left the barrier (its last action 8): P3.
    fn leave(&self, s: &mut State, p: usize, mode: Mode, viol: &mut Viols) {
        if mode != Mode::Main {
            s.rec |= 1 << p;
            return;
        }
        for &q in &self.partners[p] {
            if self.at_start(s, q) {
                continue;
            }
            let where_ = if self.stopped(s, q) {
                "stopped".to_string()
            } else if self.ended(s, q) {
                "ended".to_string()
            } else {
                format!("at {:?}", self.ops[q][s.p[q].pc as usize])
            };
            if !bit(s.p[p].met, q) {
                viol.push((
                    Prop::P3,
                    format!(
                        "{} left the barrier while partner {} is {} in a cycle it began before {}'s session started",
                        self.names[p], self.names[q], where_, self.names[p]
                    ),
                ));
            } else if s.p[q].run != s.p[p].run {
                viol.push((
                    Prop::P3,
                    format!(
                        "{} left the barrier while partner {} is {} in another cell run",
                        self.names[p], self.names[q], where_
                    ),
                ));
            }
        }
        for &q in &self.partners[p] {
            s.p[q].met |= 1 << p;
        }
    }

    /// Cell runs `a` and `b` are one from now on.
    fn union(&self, s: &mut State, a: u8, b: u8, viol: &mut Viols) {
        if a == b || a == NONE || b == NONE {
            return;
        }
        let (t, o) = (a.min(b), a.max(b));
        let (rt, ro) = (s.runs[t as usize], s.runs[o as usize]);
        let both = rt.members & ro.members;
        if both != 0 {
            let q = both.trailing_zeros() as usize;
            viol.push((
                Prop::Bridge,
                format!("two sessions of {} are in one cell run", self.names[q]),
            ));
        }
        let mut m = rt;
        m.members |= ro.members;
        for k in 0..MAXS {
            m.counts[k] = (m.counts[k] + ro.counts[k]).min(COUNT_CAP);
        }
        s.runs[t as usize] = m;
        s.runs[o as usize] = Run::default();
        for x in s.p[..self.n].iter_mut() {
            if x.run == o {
                x.run = t;
            }
            if x.held.run == o {
                x.held.run = t;
            }
        }
        for w in s.r.iter_mut().chain(s.s.iter_mut()).chain(s.k.iter_mut()) {
            if w.1.run == o {
                w.1.run = t;
            }
        }
        for &(a, b) in &self.deps {
            if m.counts[b] > m.counts[a] {
                viol.push((
                    Prop::P2,
                    format!(
                        "two cell runs became one: step {} ran {} time(s) in it, {} only {}",
                        self.steps[b], m.counts[b], self.steps[a], m.counts[a]
                    ),
                ));
            }
        }
    }

    /// Renames sessions (per program) and cell runs by first appearance, drops dead runs.
    fn canon(&self, s: &mut State) {
        fn remap(map: &mut Vec<(u8, u8)>, old: u8) -> u8 {
            if old == NONE {
                return NONE;
            }
            if let Some(&(_, n)) = map.iter().find(|(o, _)| *o == old) {
                return n;
            }
            let n = map.len() as u8;
            map.push((old, n));
            n
        }
        let mut map = Vec::with_capacity(8);
        for p in 0..self.n {
            map.clear();
            map.push((s.p[p].sess, 0));
            s.p[p].sess = 0;
            for (w, &(a, _)) in self.pairs.iter().enumerate() {
                if a == p {
                    s.r[w].1.sess = remap(&mut map, s.r[w].1.sess);
                }
            }
            for (c, &(t, h)) in self.chans.iter().enumerate() {
                if t == p {
                    s.s[c].1.sess = remap(&mut map, s.s[c].1.sess);
                }
                if h == p {
                    s.k[c].1.sess = remap(&mut map, s.k[c].1.sess);
                }
            }
            for x in 0..self.n {
                if self.held_from(s, x) == Some(p) {
                    s.p[x].held.sess = remap(&mut map, s.p[x].held.sess);
                }
            }
        }
        map.clear();
        // Runs of sessions and of R wires may still merge: they keep members and counts; runs
        // named only by S and K tags are compared, never merged.
        for p in 0..self.n {
            s.p[p].run = remap(&mut map, s.p[p].run);
        }
        for w in s.r.iter_mut() {
            w.1.run = remap(&mut map, w.1.run);
        }
        let live = map.len();
        for w in s.s.iter_mut().chain(s.k.iter_mut()) {
            w.1.run = remap(&mut map, w.1.run);
        }
        for x in s.p[..self.n].iter_mut() {
            x.held.run = remap(&mut map, x.held.run);
        }
        let old = s.runs;
        s.runs = [Run::default(); MAXRUN];
        for &(o, n) in &map[..live] {
            s.runs[n as usize] = old[o as usize];
        }
    }

    /// The partner whose K or S level program `x` holds between a wait and its check.
    fn held_from(&self, s: &State, x: usize) -> Option<usize> {
        if s.p[x].pc & STOPPED != 0 {
            return None;
        }
        match self.ops[x][s.p[x].pc as usize] {
            Op::TellCheck { c, .. } => Some(self.chans[c].1),
            Op::HearCheck { c, .. } => Some(self.chans[c].0),
            _ => None,
        }
    }

    /// The state without ghosts (for P5).
    fn strip(&self, st: &State) -> State {
        let mut s = st.clone();
        for p in 0..MAXP {
            let x = &mut s.p[p];
            x.cycles = 0;
            x.sess = 0;
            x.met = 0;
            x.run = NONE;
            x.seen = 0;
            x.held = TAG0;
        }
        for w in s.r.iter_mut().chain(s.s.iter_mut()).chain(s.k.iter_mut()) {
            w.1 = TAG0;
        }
        s.runs = [Run::default(); MAXRUN];
        s.faults = 0;
        s
    }

    /// Every transition from `st`: (label, successor, violations on the way).
    fn successors(&self, st: &State, mode: Mode, out: &mut Vec<(Label, State, Viols)>) {
        for p in 0..self.n {
            let lab = |ev| Label { ev, p: p as u8 };
            if self.stopped(st, p) {
                let mut s = st.clone();
                self.restart(&mut s, p, Ev::Operator);
                out.push((lab(Ev::Operator), s, Vec::new()));
                continue;
            }
            if self.ended(st, p) {
                if mode == Mode::Recovery || st.p[p].cycles + 1 < self.cycles {
                    let mut s = st.clone();
                    self.restart(&mut s, p, Ev::Next);
                    out.push((lab(Ev::Next), s, Vec::new()));
                }
                continue;
            }
            let mut v = Vec::new();
            if let Some(s) = self.act(st, p, mode, &mut v) {
                out.push((lab(Ev::Act), s, v));
            }
            if mode == Mode::Main && st.faults < self.max_faults {
                let mut s = st.clone();
                self.restart(&mut s, p, Ev::Fault);
                out.push((lab(Ev::Fault), s, Vec::new()));
            }
        }
        for (_, s, _) in out.iter_mut() {
            match mode {
                Mode::Main => self.canon(s),
                Mode::Recovery => *s = self.strip(s),
            }
        }
    }

    /// Replays `labels` from the initial state and prints what each does.
    /// The state `labels` lead to from the initial state.
    fn state_after(&self, labels: &[Label]) -> State {
        let mut st = self.init();
        let mut succ = Vec::new();
        for l in labels {
            succ.clear();
            self.successors(&st, Mode::Main, &mut succ);
            st = succ
                .drain(..)
                .find(|(x, _, _)| x.ev == l.ev && x.p == l.p)
                .expect("replay")
                .1;
        }
        st
    }

    fn trace_text(&self, labels: &[Label]) -> String {
        self.replay(self.init(), labels, Mode::Main, 1)
    }

    /// Replays `labels` from `st` in `mode`, numbering the lines from `first`.
    fn replay(&self, mut st: State, labels: &[Label], mode: Mode, first: usize) -> String {
        let mut out = String::new();
        for (i, l) in labels.iter().enumerate() {
            let mut succ = Vec::new();
            self.successors(&st, mode, &mut succ);
            let (_, next, _) = succ
                .into_iter()
                .find(|(m, _, _)| m.ev == l.ev && m.p == l.p)
                .expect("replay");
            let p = l.p as usize;
            let name = self.names[p];
            let text = match l.ev {
                Ev::Fault => format!("FAULT: {name} restarts"),
                Ev::Operator => format!("operator restarts stopped {name}"),
                Ev::Next => format!("{name} ended, restarted for its next cycle"),
                Ev::Act => {
                    let op = self.ops[p][st.p[p].pc as usize];
                    let stop = next.p[p].pc & STOPPED != 0;
                    let mut t = match op {
                        Op::SetR { w, v } => format!("R_{} := {}", self.wire_name(w), v as u8),
                        Op::SetB { w, v } => format!("B_{} := {}", self.wire_name(w), v as u8),
                        Op::ResetS(c) => format!("S_{} := 0", self.chan_name(c)),
                        Op::ResetK(c) => format!("K_{} := 0", self.chan_name(c)),
                        Op::WaitR0 => "wait R_*->me == 0: passes".into(),
                        Op::WaitB1 => "wait B_*->me == 1: passes".into(),
                        Op::WaitGo if self.restarted_partner(&st, p) => {
                            "wait: a partner shows R==0 and B==0: passes".into()
                        }
                        Op::WaitGo => "wait: every partner R==1: passes".into(),
                        Op::StopIfRestarted { .. } if stop => {
                            "a partner restarted (R==0, B==0) -> STOP".into()
                        }
                        Op::StopIfRestarted { .. } if next.p[p].pc == 0 => {
                            "a partner restarted (R==0, B==0) -> back to action 1".into()
                        }
                        Op::StopIfRestarted { .. } => "no partner restarted: go on".into(),
                        Op::StopUnlessRunning if stop => "not every partner R==1 -> STOP".into(),
                        Op::StopUnlessRunning => "every partner R==1: go on".into(),
                        Op::WaitGoFirst => "wait R==1 or B==0: passes".into(),
                        Op::Step(id) => format!("step {}", self.steps[id]),
                        Op::TellWait { c, j } => {
                            let q = self.chans[c].1;
                            let ch = self.chan_name(c);
                            if st.k[c].0 == bit(st.p[p].tx, c) {
                                format!("Tell {ch}#{j}: wait passes on K_{ch} == tx")
                            } else {
                                format!(
                                    "Tell {ch}#{j}: wait passes on R_{} == 0",
                                    self.wire_name(self.w(q, p))
                                )
                            }
                        }
                        Op::TellCheck { c, j } if stop => {
                            format!("Tell {}#{j}: R == 0 -> STOP", self.chan_name(c))
                        }
                        Op::TellCheck { c, j } => {
                            format!("Tell {}#{j}: R == 1, go on", self.chan_name(c))
                        }
                        Op::TellSet { c, .. } => {
                            format!("S_{} := {}", self.chan_name(c), bit(next.p[p].tx, c) as u8)
                        }
                        Op::HearWait { c, j, .. } => {
                            let q = self.chans[c].0;
                            let ch = self.chan_name(c);
                            if st.s[c].0 != bit(st.p[p].rx, c) {
                                format!("Hear {ch}#{j}: wait passes on S_{ch} == rx")
                            } else {
                                format!(
                                    "Hear {ch}#{j}: wait passes on R_{} == 0",
                                    self.wire_name(self.w(q, p))
                                )
                            }
                        }
                        Op::HearCheck { c, j } if stop => {
                            format!("Hear {}#{j}: R == 0 -> STOP", self.chan_name(c))
                        }
                        Op::HearCheck { c, j } => {
                            format!("Hear {}#{j}: R == 1, go on", self.chan_name(c))
                        }
                        Op::HearSet { c, .. } => {
                            format!("K_{} := {}", self.chan_name(c), bit(next.p[p].rx, c) as u8)
                        }
                        Op::EndWait { c, .. } => {
                            format!("end wait on K_{}: passes", self.chan_name(c))
                        }
                        Op::End => unreachable!(),
                    };
                    if !stop && st.p[p].pc as usize == self.leave_op[p] {
                        t.push_str("  (leaves the barrier)");
                    }
                    if !stop && next.p[p].pc as usize == self.end_op[p] {
                        t.push_str("  -> END");
                    }
                    format!("{name}: {t}")
                }
            };
            let _ = writeln!(out, "  {:3}. {text}", i + first);
            st = next;
        }
        out
    }
}

fn nth(body: &[Item], f: impl Fn(&Item) -> bool, j: usize) -> Option<usize> {
    body.iter()
        .enumerate()
        .filter(|(_, it)| f(it))
        .nth(j)
        .map(|(i, _)| i)
}

// ---------------------------------------------------------------------------------------------
// Exploration
// ---------------------------------------------------------------------------------------------

/// FxHash (as in rustc): the state tables hash small states millions of times, SipHash's
/// resistance to chosen keys is not needed here.
#[derive(Default)]
struct Fx(u64);

impl Fx {
    fn add(&mut self, w: u64) {
        self.0 = (self.0.rotate_left(5) ^ w).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

impl Hasher for Fx {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.add(u64::from_le_bytes(c.try_into().unwrap()));
        }
        for &b in chunks.remainder() {
            self.add(b as u64);
        }
    }
    fn write_u8(&mut self, i: u8) {
        self.add(i as u64);
    }
    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }
}

type Map<K, V> = HashMap<K, V, BuildHasherDefault<Fx>>;

struct Found {
    prop: Prop,
    msg: String,
    trace: Vec<Label>,
}

struct Outcome {
    label: String,
    states: usize,
    transitions: usize,
    /// First (shortest) counter-example per property, and how many transitions violate it.
    found: Vec<(Found, usize)>,
    /// Reachable states where no program can move and none is ended or stopped.
    all_blocked: usize,
    all_blocked_trace: Option<Vec<Label>>,
    /// States where no program can move, some wait, the others are ended or stopped.
    need_operator: usize,
    /// States where every program has ended its last cycle.
    finals: usize,
    rec_starts: usize,
    rec_states: usize,
    /// Recovery starts from which no whole cycle of every program can be reached.
    ef_fail: usize,
    ef_fail_trace: Option<Vec<Label>>,
    /// Recovery starts from which some path avoids completion forever.
    af_fail: usize,
    /// One such path: main trace to the start, recovery labels, index where the loop begins.
    af_loop: Option<(Vec<Label>, Vec<Label>, Option<usize>)>,
    /// Recovery states on a never-completing loop that has no STOP (0: every such loop needs
    /// the operator to restart a stopped program in each round).
    stop_free_loop_states: usize,
    /// The exploration hit its state limit (safety checked on the part explored, P5 not).
    partial: bool,
    millis: u128,
}

impl Outcome {
    fn holds(&self, p: Prop) -> bool {
        !self.found.iter().any(|(f, _)| f.prop == p)
    }
    fn p5_holds(&self) -> bool {
        self.all_blocked == 0 && self.ef_fail == 0
    }
    fn summary(&self) -> String {
        let mut t = format!(
            "{}: {}{} states, {} transitions; P1 {} P2 {} P3 {} P4 {} P5 {}; two-rounds-in-one-run {}; all-blocked {}, waiting-for-operator {}, all-ended {}; recovery: {} starts, {} states, cannot complete {}, may loop without completing {} (on loops without STOP: {}); {} ms",
            self.label,
            if self.partial {
                "PARTIAL (stopped early) "
            } else {
                ""
            },
            self.states,
            self.transitions,
            ok(self.holds(Prop::P1)),
            ok(self.holds(Prop::P2)),
            ok(self.holds(Prop::P3)),
            ok(self.holds(Prop::P4)),
            if !self.p5_holds() {
                "VIOLATED"
            } else if self.partial {
                "not checked"
            } else {
                "holds"
            },
            if self.holds(Prop::Bridge) {
                "never"
            } else {
                "SEEN"
            },
            self.all_blocked,
            self.need_operator,
            self.finals,
            self.rec_starts,
            self.rec_states,
            self.ef_fail,
            self.af_fail,
            self.stop_free_loop_states,
            self.millis
        );
        for (f, count) in &self.found {
            let _ = write!(
                t,
                "\n  {:?} violated ({count} transitions), e.g.: {}",
                f.prop, f.msg
            );
        }
        t
    }
}

fn ok(b: bool) -> &'static str {
    if b { "holds" } else { "VIOLATED" }
}

fn trace_of(parents: &[(u32, Label)], mut i: u32) -> Vec<Label> {
    let mut t = Vec::new();
    while i != 0 {
        let (p, l) = parents[i as usize];
        t.push(l);
        i = p;
    }
    t.reverse();
    t
}

/// When an exploration may end before it has seen every reachable state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stop {
    /// Only at the state limit.
    Never,
    /// At the first violation of P1-P4 or the first state where every program waits forever.
    Any,
    /// At the first state where every program waits forever.
    Deadlock,
}

/// Explores every interleaving, breadth-first; `limit` states at most, and ends early as `stop`
/// says (the outcome is then `partial` and P5 (b) is not checked).
fn check(
    spec: &Spec,
    variant: Variant,
    cycles: u8,
    faults: u8,
    limit: usize,
    stop: Stop,
) -> (Model, Outcome) {
    let m = Model::new(spec, variant, cycles, faults);
    let start = Instant::now();
    let mut index: Map<State, u32> = Map::default();
    let mut parents: Vec<(u32, Label)> = Vec::new();
    let mut queue: VecDeque<State> = VecDeque::new();
    let init = m.init();
    index.insert(init.clone(), 0);
    parents.push((0, Label { ev: Ev::Act, p: 0 }));
    queue.push_back(init);
    let mut found: Vec<(Found, usize)> = Vec::new();
    let mut transitions = 0usize;
    let mut all_blocked = 0;
    let mut all_blocked_trace = None;
    let mut need_operator = 0;
    let mut finals = 0;
    let mut rec_start_of: Map<State, u32> = Map::default();
    let mut succ = Vec::new();
    let mut i: u32 = 0;
    let mut partial = false;
    while let Some(st) = queue.pop_front() {
        let stop_now = match stop {
            Stop::Never => false,
            Stop::Any => all_blocked > 0 || found.iter().any(|(f, _)| f.prop != Prop::Bridge),
            Stop::Deadlock => all_blocked > 0,
        };
        if parents.len() >= limit || stop_now {
            partial = true;
            break;
        }
        succ.clear();
        m.successors(&st, Mode::Main, &mut succ);
        let mut can_move = false;
        for (lab, next, viol) in succ.drain(..) {
            transitions += 1;
            if lab.ev == Ev::Act {
                can_move = true;
            }
            for (prop, msg) in viol {
                if let Some(e) = found.iter_mut().find(|(f, _)| f.prop == prop) {
                    e.1 += 1;
                } else {
                    let mut trace = trace_of(&parents, i);
                    trace.push(lab);
                    found.push((Found { prop, msg, trace }, 1));
                }
            }
            if let Entry::Vacant(e) = index.entry(next) {
                queue.push_back(e.key().clone());
                e.insert(parents.len() as u32);
                parents.push((i, lab));
            }
        }
        if !can_move {
            let idle = (0..m.n)
                .filter(|&p| m.ended(&st, p) || m.stopped(&st, p))
                .count();
            if idle == 0 {
                all_blocked += 1;
                if all_blocked_trace.is_none() {
                    all_blocked_trace = Some(trace_of(&parents, i));
                }
            } else if idle < m.n {
                need_operator += 1;
            } else if (0..m.n).all(|p| m.ended(&st, p) && st.p[p].cycles + 1 == cycles) {
                finals += 1;
            }
        }
        rec_start_of.entry(m.strip(&st)).or_insert(i);
        i += 1;
    }
    let states = parents.len();
    drop(index);
    drop(queue);

    // P5: from the ghost-free image of every reachable state, with no more faults and the
    // operator restarting ended and stopped programs at any time, can every program complete a
    // whole cycle (leave the barrier, then END)? EF by backward reachability; AF by the least
    // fixpoint over the same graph.
    let all_done: u8 = ((1u8 << m.n) - 1) << 4;
    let mut rindex: Map<State, u32> = Map::default();
    let mut rstates: Vec<State> = Vec::new();
    let mut starts: Vec<(u32, u32)> = Vec::new(); // (recovery index, main index)
    if partial {
        rec_start_of.clear();
    }
    for (s, &mi) in &rec_start_of {
        let id = rstates.len() as u32;
        rindex.insert(s.clone(), id);
        rstates.push(s.clone());
        starts.push((id, mi));
    }
    let rec_starts = starts.len();
    let mut edges_off: Vec<u32> = vec![0];
    let mut edges: Vec<u32> = Vec::new();
    let mut edge_op: Vec<bool> = Vec::new(); // the edge is an operator's restart of a stopped program
    let mut k = 0usize;
    while k < rstates.len() {
        let st = rstates[k].clone();
        if st.rec & all_done != all_done {
            succ.clear();
            m.successors(&st, Mode::Recovery, &mut succ);
            for (lab, next, _) in succ.drain(..) {
                edge_op.push(lab.ev == Ev::Operator);
                let id = match rindex.entry(next) {
                    Entry::Occupied(e) => *e.get(),
                    Entry::Vacant(e) => {
                        let id = rstates.len() as u32;
                        rstates.push(e.key().clone());
                        e.insert(id);
                        id
                    }
                };
                edges.push(id);
            }
        }
        edges_off.push(edges.len() as u32);
        k += 1;
    }
    let rn = rstates.len();
    let goal: Vec<bool> = rstates
        .iter()
        .map(|s| s.rec & all_done == all_done)
        .collect();
    let mut rev_off = vec![0u32; rn + 1];
    for &t in &edges {
        rev_off[t as usize + 1] += 1;
    }
    for x in 0..rn {
        rev_off[x + 1] += rev_off[x];
    }
    let mut rev = vec![0u32; edges.len()];
    let mut fill = rev_off.clone();
    for x in 0..rn {
        for &t in &edges[edges_off[x] as usize..edges_off[x + 1] as usize] {
            rev[fill[t as usize] as usize] = x as u32;
            fill[t as usize] += 1;
        }
    }
    // EF goal
    let mut ef = goal.clone();
    let mut work: Vec<u32> = (0..rn as u32).filter(|&x| goal[x as usize]).collect();
    while let Some(t) = work.pop() {
        for &x in &rev[rev_off[t as usize] as usize..rev_off[t as usize + 1] as usize] {
            if !ef[x as usize] {
                ef[x as usize] = true;
                work.push(x);
            }
        }
    }
    // AF goal: goal, or has successors and all of them AF.
    let mut af = goal.clone();
    let mut pending: Vec<u32> = (0..rn).map(|x| edges_off[x + 1] - edges_off[x]).collect();
    let mut work: Vec<u32> = (0..rn as u32).filter(|&x| goal[x as usize]).collect();
    while let Some(t) = work.pop() {
        for &x in &rev[rev_off[t as usize] as usize..rev_off[t as usize + 1] as usize] {
            let x = x as usize;
            if af[x] {
                continue;
            }
            pending[x] -= 1;
            if pending[x] == 0 {
                af[x] = true;
                work.push(x as u32);
            }
        }
    }
    let mut ef_fail = 0;
    let mut ef_fail_trace = None;
    let mut af_fail = 0;
    starts.sort();
    for &(r, mi) in &starts {
        if !ef[r as usize] {
            ef_fail += 1;
            if ef_fail_trace.is_none() {
                ef_fail_trace = Some(trace_of(&parents, mi));
            }
        }
        if !af[r as usize] {
            af_fail += 1;
        }
    }
    // Is there such a path without STOPs (a loop of program actions and next-cycle restarts
    // only)? Peel off, among the states outside AF, those with no such edge to another one; what
    // is left holds a cycle.
    let mut out_deg: Vec<u32> = vec![0; rn];
    for x in 0..rn {
        if af[x] {
            continue;
        }
        for e in edges_off[x] as usize..edges_off[x + 1] as usize {
            if !edge_op[e] && !af[edges[e] as usize] {
                out_deg[x] += 1;
            }
        }
    }
    let mut gone: Vec<bool> = af.clone();
    let mut work: Vec<u32> = (0..rn as u32)
        .filter(|&x| !af[x as usize] && out_deg[x as usize] == 0)
        .collect();
    for &x in &work {
        gone[x as usize] = true;
    }
    while let Some(t) = work.pop() {
        for &x in &rev[rev_off[t as usize] as usize..rev_off[t as usize + 1] as usize] {
            let x = x as usize;
            if gone[x] {
                continue;
            }
            // every edge x -> t that counts
            for e in edges_off[x] as usize..edges_off[x + 1] as usize {
                if edges[e] == t && !edge_op[e] {
                    out_deg[x] -= 1;
                }
            }
            if out_deg[x] == 0 {
                gone[x] = true;
                work.push(x as u32);
            }
        }
    }
    let stop_free_loop_states = gone.iter().filter(|g| !**g).count();

    // A path from a recovery start that never completes: follow successors outside AF until a
    // state repeats.
    let mut af_loop = None;
    if let Some(&(r0, mi)) = starts.iter().find(|&&(r, _)| !af[r as usize]) {
        let mut seen_at: HashMap<u32, usize> = HashMap::new();
        let mut labels = Vec::new();
        let mut cur = r0;
        let mut at = None; // None: the path ends in a state where nothing can move
        while !seen_at.contains_key(&cur) {
            seen_at.insert(cur, labels.len());
            succ.clear();
            m.successors(&rstates[cur as usize], Mode::Recovery, &mut succ);
            let Some((lab, next)) = succ
                .iter()
                .map(|(l, n, _)| (*l, rindex[n]))
                .find(|&(_, n)| !af[n as usize])
            else {
                break;
            };
            labels.push(lab);
            cur = next;
            at = seen_at.get(&cur).copied();
        }
        af_loop = Some((trace_of(&parents, mi), labels, at));
    }
    drop(rindex);
    let out = Outcome {
        label: format!(
            "{} [{:?}, {} cycles, {} faults]",
            m.spec_name, m.variant, cycles, faults
        ),
        states,
        transitions,
        found,
        all_blocked,
        all_blocked_trace,
        need_operator,
        finals,
        rec_starts,
        rec_states: rn,
        ef_fail,
        ef_fail_trace,
        af_fail,
        af_loop,
        stop_free_loop_states,
        partial,
        millis: start.elapsed().as_millis(),
    };
    (m, out)
}

fn report(m: &Model, o: &Outcome) {
    println!("{}", o.summary());
    for (f, _) in &o.found {
        println!(
            "--- shortest counter-example to {:?} ({} events):\n{}  => {}",
            f.prop,
            f.trace.len(),
            m.trace_text(&f.trace),
            f.msg
        );
    }
    if let Some(t) = &o.all_blocked_trace {
        let st = m.state_after(t);
        let waits: Vec<String> = (0..m.n)
            .map(|p| format!("{} at {:?}", m.names[p], m.ops[p][st.p[p].pc as usize]))
            .collect();
        println!(
            "--- every program blocked forever after:\n{}  waiting: {}",
            m.trace_text(t),
            waits.join(", ")
        );
    }
    if let Some((t, rec, at)) = &o.af_loop {
        let start = m.strip(&m.state_after(t));
        println!(
            "--- a recovery path that never completes ({}), after:\n{}  recovery:\n{}",
            match at {
                Some(at) => format!("events {}.. repeat forever", at + 1),
                None => "it ends where nothing can move".into(),
            },
            m.trace_text(t),
            m.replay(start, rec, Mode::Recovery, 1)
        );
    }
    if let Some(t) = &o.ef_fail_trace {
        println!(
            "--- no completion possible (even with the operator restarting) after:\n{}",
            m.trace_text(t)
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Bodies
// ---------------------------------------------------------------------------------------------

use Item::{Hear, Step, Tell};

/// X: [a, Tell XY]; Y: [Hear XY, b]
fn one_channel() -> Spec {
    Spec {
        name: "one channel",
        progs: vec!["X", "Y"],
        chans: vec![(0, 1)],
        bodies: vec![vec![Step("a"), Tell(0)], vec![Hear(0), Step("b")]],
    }
}

/// X: [a, Tell XY, Hear YX, c]; Y: [Hear XY, b, Tell YX]
fn both_directions() -> Spec {
    Spec {
        name: "both directions",
        progs: vec!["X", "Y"],
        chans: vec![(0, 1), (1, 0)],
        bodies: vec![
            vec![Step("a"), Tell(0), Hear(1), Step("c")],
            vec![Hear(0), Step("b"), Tell(1)],
        ],
    }
}

/// X: [a, Tell XY]; Y: [Hear XY, b, Tell YZ]; Z: [Hear YZ, c]
fn chain() -> Spec {
    Spec {
        name: "chain",
        progs: vec!["X", "Y", "Z"],
        chans: vec![(0, 1), (1, 2)],
        bodies: vec![
            vec![Step("a"), Tell(0)],
            vec![Hear(0), Step("b"), Tell(1)],
            vec![Hear(1), Step("c")],
        ],
    }
}

/// Two messages on one channel per cycle (the toggle comes back to 0 within a cycle):
/// X: [a, Tell XY, c, Tell XY]; Y: [Hear XY, b, Hear XY, d]
fn two_messages() -> Spec {
    Spec {
        name: "two messages",
        progs: vec!["X", "Y"],
        chans: vec![(0, 1)],
        bodies: vec![
            vec![Step("a"), Tell(0), Step("c"), Tell(0)],
            vec![Hear(0), Step("b"), Hear(0), Step("d")],
        ],
    }
}

/// Three programs, all partners: X: [a, Tell XY, Tell XZ]; Y: [Hear XY, b, Tell YZ];
/// Z: [Hear XZ, Hear YZ, c]
fn triangle() -> Spec {
    Spec {
        name: "triangle",
        progs: vec!["X", "Y", "Z"],
        chans: vec![(0, 1), (0, 2), (1, 2)],
        bodies: vec![
            vec![Step("a"), Tell(0), Tell(1)],
            vec![Hear(0), Step("b"), Tell(2)],
            vec![Hear(1), Hear(2), Step("c")],
        ],
    }
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

/// Checks `variant` on `spec` and prints the figures and every counter-example found.
fn run(spec: Spec, variant: Variant, cycles: u8, faults: u8, limit: usize, stop: Stop) -> Outcome {
    let (m, o) = check(&spec, variant, cycles, faults, limit, stop);
    report(&m, &o);
    o
}

fn assert_all_hold(o: &Outcome) {
    for p in [Prop::P1, Prop::P2, Prop::P3, Prop::P4] {
        assert!(o.holds(p), "{:?}: {}", p, o.summary());
    }
    assert!(o.p5_holds(), "P5: {}", o.summary());
    assert!(!o.partial, "{}", o.summary());
}

/// `variant` on `spec`: P1-P5 hold, and every recovery that never completes goes through a STOP
/// (and the operator's restart) in each round. Ends at the first violation found.
fn assert_protocol(variant: Variant, spec: Spec, cycles: u8, faults: u8) -> Outcome {
    let o = run(spec, variant, cycles, faults, usize::MAX, Stop::Any);
    assert_all_hold(&o);
    assert_eq!(o.stop_free_loop_states, 0, "{}", o.summary());
    o
}

/// The five bodies with the bounds of the default tests (`cargo test` runs in debug).
fn bodies() -> Vec<(Spec, u8, u8)> {
    vec![
        (one_channel(), 3, 2),
        (both_directions(), 3, 2),
        (two_messages(), 3, 2),
        (chain(), 2, 1),
        (triangle(), 1, 1),
    ]
}

/// The bodies of the mutation tests: those of two programs and the chain.
fn mutation_bodies() -> Vec<(Spec, u8, u8)> {
    let mut b = bodies();
    b.retain(|(s, _, _)| s.name != "triangle");
    b
}

fn bounds(name: &str) -> (Spec, u8, u8) {
    bodies().into_iter().find(|b| b.0.name == name).unwrap()
}

fn protocol(name: &str) {
    let (spec, c, f) = bounds(name);
    assert_protocol(Variant::Written, spec, c, f);
}

#[test]
fn protocol_one_channel() {
    protocol("one channel");
}

#[test]
fn protocol_both_directions() {
    protocol("both directions");
}

#[test]
fn protocol_two_messages() {
    protocol("two messages");
}

#[test]
fn protocol_chain() {
    protocol("chain");
}

/// Three programs that are all partners of each other (the body the first design deadlocks on).
#[test]
fn protocol_triangle() {
    protocol("triangle");
}

/// Beyond P5 (which asks that completion be reachable): with no more faults, the recovery can
/// go round forever (two programs pass each other's barrier out of phase, each STOPs in turn,
/// the operator restarts it); every such loop has a STOP and an operator restart in each round.
#[test]
fn protocol_recovery_can_loop_only_through_stops() {
    let o = run(
        one_channel(),
        Variant::Written,
        1,
        2,
        usize::MAX,
        Stop::Never,
    );
    assert!(o.p5_holds(), "{}", o.summary());
    assert!(o.af_fail > 0, "{}", o.summary());
    assert_eq!(o.stop_free_loop_states, 0, "{}", o.summary());
}

/// Why action 7's second read is "STOP unless every partner is running": the second design
/// read "STOP if some partner is back at its start (R_YX == 0 AND B_YX == 0)", and a partner
/// restarted inside the barrier that raised B between the two reads let the program go on
/// into its cycle, where it took a message the partner never sent.
#[test]
fn second_design_takes_a_message_never_sent() {
    let (spec, c, f) = bodies().remove(0);
    let o = run(spec, Variant::StopIfRestarted, c, f, usize::MAX, Stop::Any);
    assert!(
        !o.holds(Prop::P1) || !o.holds(Prop::P2),
        "the second design holds on one channel: {}",
        o.summary()
    );
}

/// Why action 7 STOPs: in the first design (action 7 waits until R_YX == 1 OR B_YX == 0 for
/// every partner, no stop) three programs that are all partners of each other deadlock after
/// one fault restart (X at action 7 holds R_XZ = 1 waiting for Y's go, Y at action 5 waits for
/// Z's ready, Z at action 3 waits for R_XZ = 0). Nobody is stopped, so no operator is called.
#[test]
fn first_design_triangle_deadlocks() {
    let o = run(
        triangle(),
        Variant::FirstDesign,
        1,
        1,
        usize::MAX,
        Stop::Deadlock,
    );
    assert!(o.all_blocked > 0, "{}", o.summary());
    let trace = o.all_blocked_trace.as_ref().unwrap();
    assert!(trace.len() <= 40, "{} events", trace.len());
}

/// Why STOP and not "begin again at action 1" at action 7: then the recovery can loop forever
/// without any STOP (the programs retry out of phase on their own).
#[test]
fn retry_instead_of_stop_can_loop_by_itself() {
    let o = run(one_channel(), Variant::Retry, 3, 2, usize::MAX, Stop::Never);
    assert!(o.p5_holds(), "{}", o.summary());
    assert!(o.stop_free_loop_states > 0, "{}", o.summary());
}

/// State limit of the mutation runs (each counter-example they look for is found well within).
const MUTATION_LIMIT: usize = 20_000;

/// M1: no barrier at all (actions 3-8 removed; R is never 1 again): a program leaves its start
/// while its partner is in the middle of an older cycle (P3), and every wait STOPs (P5).
#[test]
fn mutation_m1_no_barrier() {
    for (spec, c, f) in mutation_bodies() {
        let o = run(spec, Variant::NoBarrier, c, f, usize::MAX, Stop::Never);
        assert!(!o.holds(Prop::P3) && !o.p5_holds(), "{}", o.summary());
    }
}

/// M1b: actions 3-5, 7, 8 removed but R := 1 kept: stale messages and acks are taken.
#[test]
fn mutation_m1b_no_barrier_keep_go() {
    for (spec, c, f) in mutation_bodies() {
        let o = run(
            spec,
            Variant::NoBarrierKeepGo,
            c,
            f,
            MUTATION_LIMIT,
            Stop::Never,
        );
        assert!(
            !o.holds(Prop::P2) && !o.holds(Prop::P3) && !o.holds(Prop::P4),
            "{}",
            o.summary()
        );
    }
}

/// M2: a Hear waits `until S == rx` (no R guard, no STOP): it takes a message of the teller's
/// previous session (P1, P4) and waits forever for one that never comes (P5).
#[test]
fn mutation_m2_hear_without_guard() {
    for (spec, c, f) in mutation_bodies() {
        let o = run(
            spec,
            Variant::HearNoGuard,
            c,
            f,
            MUTATION_LIMIT,
            Stop::Never,
        );
        assert!(
            !o.holds(Prop::P1) && !o.holds(Prop::P4) && !o.p5_holds(),
            "{}",
            o.summary()
        );
    }
}

/// M3: action 2 (strobe, ack and ready resets) before action 1 (R := 0): a Tell takes the
/// restarted hearer's reset ack as the ack it waits for (P1).
#[test]
fn mutation_m3_reset_before_run() {
    for (spec, c, f) in mutation_bodies() {
        let o = run(
            spec,
            Variant::ResetBeforeR,
            c,
            f,
            MUTATION_LIMIT,
            Stop::Never,
        );
        let reset_ack = o.found.iter().any(|(x, _)| {
            x.prop == Prop::P1 && x.msg.contains("Tell") && x.msg.contains("(its reset)")
        });
        assert!(reset_ack, "{}", o.summary());
    }
}

/// Bigger bounds, the written protocol (release: `cargo test --release --test protocol_model
/// -- --ignored`).
#[test]
#[ignore]
fn bigger_bounds() {
    let specs = vec![
        (one_channel(), 4, 3),
        (both_directions(), 4, 3),
        (two_messages(), 4, 3),
        (chain(), 3, 1),
        (chain(), 3, 2),
        (chain(), 4, 1),
        (triangle(), 2, 1),
        (triangle(), 3, 1),
        (triangle(), 2, 2),
    ];
    for (spec, c, f) in specs {
        assert_protocol(Variant::Written, spec, c, f);
    }
}

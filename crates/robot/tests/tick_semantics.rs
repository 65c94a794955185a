//! The tick semantics of the behavior-tree and state-machine engines, as tables
//! (`docs/tick-semantics.md`; design principle 6). Each row is one scenario; a failing row names
//! itself, the step and what actually happened. If a row has to change, the documented semantics
//! changed: update the module documentation and `docs/tick-semantics.md` with it.

use std::collections::BTreeSet;
use std::time::Duration;

use strata_robot::control::bt::{
    Node, Status, Subtree, Threshold, Tree, action, action_with_halt, condition, force_failure,
    force_success, inverter, leaf, parallel, rate_limit, reactive_selector, reactive_sequence,
    retry, selector, sequence, timeout,
};
use strata_robot::control::hsm::{BuildError, Fired, State, StateMachine};
use strata_runtime::Time;

fn at(secs: f64) -> Time {
    Time::from_secs_f64(secs)
}

fn secs(secs: f64) -> Duration {
    Duration::from_secs_f64(secs)
}

fn status_letter(status: Status) -> char {
    match status {
        Status::Running => 'R',
        Status::Success => 'S',
        Status::Failure => 'F',
    }
}

// =============================================================================================
// Behavior trees

/// The context of the behavior-tree tables: the scenario's tick number (which selects the
/// scripted statuses) and what the nodes did.
#[derive(Default)]
struct Log {
    tick: usize,
    events: Vec<(Event, String)>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Event {
    Start,
    Tick,
    Halt,
}

impl Log {
    fn names(&self, kind: Event) -> String {
        let names: Vec<&str> =
            self.events.iter().filter(|(k, _)| *k == kind).map(|(_, n)| n.as_str()).collect();
        names.join(" ")
    }
}

/// A leaf that returns, at tick `k` of the scenario, the `k`-th letter of its script (`R`, `S`,
/// `F`), and logs its ticks and halts.
struct Scripted {
    name: String,
    script: Vec<Status>,
}

impl Node<Log> for Scripted {
    fn start(&mut self, log: &mut Log, _now: Time) {
        log.events.push((Event::Start, self.name.clone()));
    }

    fn tick(&mut self, log: &mut Log, _now: Time) -> Status {
        log.events.push((Event::Tick, self.name.clone()));
        match self.script.get(log.tick) {
            Some(&status) => status,
            None => panic!("{} ticked at tick {}, past its script", self.name, log.tick),
        }
    }

    fn halt(&mut self, log: &mut Log) {
        log.events.push((Event::Halt, self.name.clone()));
    }

    fn name(&self) -> &str {
        &self.name
    }
}

fn scripted(name: &str, script: &str) -> Subtree<Log> {
    let script = script
        .chars()
        .map(|c| match c {
            'R' => Status::Running,
            'S' => Status::Success,
            'F' => Status::Failure,
            other => panic!("bad script letter {other:?}"),
        })
        .collect();
    leaf(Scripted { name: name.to_owned(), script })
}

/// An application-defined decorator: passes its child's status through and logs its own halt,
/// which the engine calls only after the child's subtree was halted.
struct Probe {
    name: &'static str,
    child: [Subtree<Log>; 1],
}

impl Node<Log> for Probe {
    fn tick(&mut self, log: &mut Log, now: Time) -> Status {
        self.child[0].tick(log, now)
    }

    fn halt(&mut self, log: &mut Log) {
        log.events.push((Event::Halt, self.name.to_owned()));
    }

    fn name(&self) -> &str {
        self.name
    }

    fn children(&self) -> &[Subtree<Log>] {
        &self.child
    }

    fn children_mut(&mut self) -> &mut [Subtree<Log>] {
        &mut self.child
    }
}

fn probe(name: &'static str, child: Subtree<Log>) -> Subtree<Log> {
    leaf(Probe { name, child: [child] })
}

/// An application-defined composite that ticks all its children and succeeds at once, leaving
/// them running: the engine must halt them.
struct Sloppy {
    children: Vec<Subtree<Log>>,
}

impl Node<Log> for Sloppy {
    fn tick(&mut self, log: &mut Log, now: Time) -> Status {
        for child in &mut self.children {
            child.tick(log, now);
        }
        Status::Success
    }

    fn name(&self) -> &str {
        "sloppy"
    }

    fn children(&self) -> &[Subtree<Log>] {
        &self.children
    }

    fn children_mut(&mut self) -> &mut [Subtree<Log>] {
        &mut self.children
    }
}

/// One step of a behavior-tree scenario.
#[derive(Debug)]
enum Step {
    /// Tick at this time (seconds); expect this status letter, these leaves ticked and these
    /// nodes halted during the tick (space-separated, in order).
    Tick(f64, char, &'static str, &'static str),
    /// `Tree::halt`; expect these nodes halted, in order.
    Halt(&'static str),
    /// The active path now.
    Path(&'static str),
}
use Step::{Halt, Path, Tick};

/// A scenario: the leaves `A`, `B`, `C`, ... follow the scripts, `shape` builds the tree
/// around them.
struct Row {
    scenario: &'static str,
    scripts: &'static [&'static str],
    shape: fn(Vec<Subtree<Log>>) -> Subtree<Log>,
    steps: &'static [Step],
}

fn one(mut leaves: Vec<Subtree<Log>>) -> Subtree<Log> {
    assert_eq!(leaves.len(), 1, "this shape takes one leaf");
    leaves.remove(0)
}

fn run(rows: &[Row]) {
    let mut failures = Vec::new();
    for row in rows {
        let leaves = row
            .scripts
            .iter()
            .enumerate()
            .map(|(i, script)| scripted(&((b'A' + i as u8) as char).to_string(), script))
            .collect();
        let mut tree = Tree::new((row.shape)(leaves));
        let mut log = Log::default();
        for (i, step) in row.steps.iter().enumerate() {
            log.events.clear();
            let actual = match *step {
                Tick(t, status, ticked, halted) => {
                    let got = tree.tick(&mut log, at(t));
                    log.tick += 1;
                    let actual =
                        (status_letter(got), log.names(Event::Tick), log.names(Event::Halt));
                    (actual != (status, ticked.to_owned(), halted.to_owned()))
                        .then(|| format!("got {actual:?}"))
                }
                Halt(halted) => {
                    tree.halt(&mut log);
                    let actual = log.names(Event::Halt);
                    (actual != halted).then(|| format!("halted {actual:?}"))
                }
                Path(path) => {
                    let actual = tree.active_path();
                    (actual != path).then(|| format!("path {actual:?}"))
                }
            };
            if let Some(actual) = actual {
                failures.push(format!("{}: step {i} {step:?}: {actual}", row.scenario));
            }
        }
    }
    assert!(failures.is_empty(), "{} failing rows:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn sequence_with_memory() {
    run(&[
        Row {
            scenario: "all children succeed in one tick",
            scripts: &["S", "S"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'S', "A B", "")],
        },
        Row {
            scenario: "resumes at the running child without re-ticking earlier ones",
            scripts: &["SSS", "RRS"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'R', "B", ""), Tick(2.0, 'S', "B", "")],
        },
        Row {
            scenario: "an earlier child that would now fail is not re-checked",
            scripts: &["SF", "RS"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'S', "B", "")],
        },
        Row {
            scenario: "a failure ends the run; the next tick starts at the first child",
            scripts: &["SS", "FS"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'F', "A B", ""), Tick(1.0, 'S', "A B", "")],
        },
        Row {
            scenario: "a failing first child: later children are not ticked",
            scripts: &["F", "S"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'F', "A", "")],
        },
        Row {
            scenario: "after success the next tick starts anew",
            scripts: &["SS", "SS"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'S', "A B", ""), Tick(1.0, 'S', "A B", "")],
        },
    ]);
}

#[test]
fn reactive_sequence_semantics() {
    run(&[
        Row {
            scenario: "earlier children are re-ticked every tick",
            scripts: &["SSS", "RRS"],
            shape: |c| reactive_sequence("rseq", c),
            steps: &[
                Tick(0.0, 'R', "A B", ""),
                Tick(1.0, 'R', "A B", ""),
                Tick(2.0, 'S', "A B", ""),
            ],
        },
        Row {
            scenario: "an earlier child failing halts the running later child",
            scripts: &["SF", "RR"],
            shape: |c| reactive_sequence("rseq", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'F', "A", "B")],
        },
        Row {
            scenario: "an earlier child running halts the running later child, which restarts",
            scripts: &["SRS", "RRR"],
            shape: |c| reactive_sequence("rseq", c),
            steps: &[
                Tick(0.0, 'R', "A B", ""),
                Tick(1.0, 'R', "A", "B"),
                Tick(2.0, 'R', "A B", ""),
            ],
        },
        Row {
            scenario: "a middle child running halts the last one only",
            scripts: &["SS", "SR", "RR"],
            shape: |c| reactive_sequence("rseq", c),
            steps: &[Tick(0.0, 'R', "A B C", ""), Tick(1.0, 'R', "A B", "C")],
        },
        Row {
            scenario: "a running child that finishes is not halted",
            scripts: &["SS", "RS"],
            shape: |c| reactive_sequence("rseq", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'S', "A B", "")],
        },
    ]);
}

#[test]
fn selector_with_memory() {
    run(&[
        Row {
            scenario: "the first success wins; later children are not ticked",
            scripts: &["S", "S"],
            shape: |c| selector("sel", c),
            steps: &[Tick(0.0, 'S', "A", "")],
        },
        Row {
            scenario: "falls back in order",
            scripts: &["F", "S"],
            shape: |c| selector("sel", c),
            steps: &[Tick(0.0, 'S', "A B", "")],
        },
        Row {
            scenario: "resumes at the running child; a higher priority is not re-checked",
            scripts: &["FS", "RR"],
            shape: |c| selector("sel", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'R', "B", "")],
        },
        Row {
            scenario: "fails when the last child fails",
            scripts: &["FF", "RF"],
            shape: |c| selector("sel", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'F', "B", "")],
        },
        Row {
            scenario: "after failure the next tick starts anew",
            scripts: &["FF", "FF"],
            shape: |c| selector("sel", c),
            steps: &[Tick(0.0, 'F', "A B", ""), Tick(1.0, 'F', "A B", "")],
        },
    ]);
}

#[test]
fn reactive_selector_semantics() {
    run(&[
        Row {
            scenario: "a higher priority succeeding halts the running fallback",
            scripts: &["FS", "RR"],
            shape: |c| reactive_selector("rsel", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'S', "A", "B")],
        },
        Row {
            scenario: "a higher priority running halts the running fallback",
            scripts: &["FR", "RR"],
            shape: |c| reactive_selector("rsel", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'R', "A", "B")],
        },
        Row {
            scenario: "the fallback keeps running while the higher priority fails",
            scripts: &["FFF", "RRS"],
            shape: |c| reactive_selector("rsel", c),
            steps: &[
                Tick(0.0, 'R', "A B", ""),
                Tick(1.0, 'R', "A B", ""),
                Tick(2.0, 'S', "A B", ""),
            ],
        },
        Row {
            scenario: "a middle child succeeding halts the last one only",
            scripts: &["FF", "FS", "RR"],
            shape: |c| reactive_selector("rsel", c),
            steps: &[Tick(0.0, 'R', "A B C", ""), Tick(1.0, 'S', "A B", "C")],
        },
    ]);
}

#[test]
fn parallel_thresholds() {
    use Threshold::{All, Any, AtLeast};
    run(&[
        Row {
            scenario: "All/Any: succeeds when all succeeded; finished children are not re-ticked",
            scripts: &["S", "RS"],
            shape: |c| parallel("par", All, Any, c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'S', "B", "")],
        },
        Row {
            scenario: "All/Any: one failure fails and halts the running children",
            scripts: &["RF", "RR", "RR"],
            shape: |c| parallel("par", All, Any, c),
            steps: &[Tick(0.0, 'R', "A B C", ""), Tick(1.0, 'F', "A B C", "B C")],
        },
        Row {
            scenario: "Any/All: one success succeeds and halts the running children",
            scripts: &["RS", "RR"],
            shape: |c| parallel("par", Any, All, c),
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'S', "A B", "B")],
        },
        Row {
            scenario: "AtLeast(2)/Any: two successes suffice",
            scripts: &["S", "RS", "RR"],
            shape: |c| parallel("par", AtLeast(2), Any, c),
            steps: &[Tick(0.0, 'R', "A B C", ""), Tick(1.0, 'S', "B C", "C")],
        },
        Row {
            scenario: "AtLeast(2)/AtLeast(2): one failure is tolerated",
            scripts: &["F", "S", "RS"],
            shape: |c| parallel("par", AtLeast(2), AtLeast(2), c),
            steps: &[Tick(0.0, 'R', "A B C", ""), Tick(1.0, 'S', "C", "")],
        },
        Row {
            scenario: "AtLeast(2)/All: fails as soon as success is out of reach",
            scripts: &["F", "RF", "RR"],
            shape: |c| parallel("par", AtLeast(2), All, c),
            steps: &[Tick(0.0, 'R', "A B C", ""), Tick(1.0, 'F', "B C", "C")],
        },
        Row {
            scenario: "AtLeast(3) with two children: never reached, fails at once",
            scripts: &["R", "R"],
            shape: |c| parallel("par", AtLeast(3), Any, c),
            steps: &[Tick(0.0, 'F', "A B", "A B")],
        },
        Row {
            scenario: "Any/Any: failure wins a tie",
            scripts: &["S", "F"],
            shape: |c| parallel("par", Any, Any, c),
            steps: &[Tick(0.0, 'F', "A B", "")],
        },
        Row {
            scenario: "a finished parallel starts anew",
            scripts: &["SS", "SS"],
            shape: |c| parallel("par", All, Any, c),
            steps: &[Tick(0.0, 'S', "A B", ""), Tick(1.0, 'S', "A B", "")],
        },
    ]);
}

#[test]
fn timeout_decorator() {
    run(&[
        Row {
            scenario: "at the deadline: halts the child without ticking it, and fails",
            scripts: &["RRRR"],
            shape: |c| timeout(secs(2.0), one(c)),
            steps: &[
                Tick(0.0, 'R', "A", ""),
                Tick(1.0, 'R', "A", ""),
                Tick(1.9, 'R', "A", ""),
                Tick(2.0, 'F', "", "A"),
            ],
        },
        Row {
            scenario: "the deadline counts from the decorator's first tick",
            scripts: &["RRR"],
            shape: |c| timeout(secs(2.0), one(c)),
            steps: &[Tick(10.0, 'R', "A", ""), Tick(11.5, 'R', "A", ""), Tick(12.0, 'F', "", "A")],
        },
        Row {
            scenario: "a child finishing in time passes through; the next run has a new deadline",
            scripts: &["RSRRR"],
            shape: |c| timeout(secs(2.0), one(c)),
            steps: &[
                Tick(0.0, 'R', "A", ""),
                Tick(1.5, 'S', "A", ""),
                Tick(3.0, 'R', "A", ""),
                Tick(4.9, 'R', "A", ""),
                Tick(5.0, 'F', "", "A"),
            ],
        },
        Row {
            scenario: "a child failing in time passes through",
            scripts: &["RF"],
            shape: |c| timeout(secs(2.0), one(c)),
            steps: &[Tick(0.0, 'R', "A", ""), Tick(1.0, 'F', "A", "")],
        },
        Row {
            scenario: "halting restarts the deadline",
            scripts: &["RRR"],
            shape: |c| timeout(secs(2.0), one(c)),
            steps: &[
                Tick(0.0, 'R', "A", ""),
                Halt("A"),
                Tick(5.0, 'R', "A", ""),
                Tick(6.5, 'R', "A", ""),
                Tick(7.0, 'F', "", "A"),
            ],
        },
    ]);
}

#[test]
fn retry_decorator() {
    run(&[
        Row {
            scenario: "a failed child is re-run on the next tick",
            scripts: &["FFS"],
            shape: |c| retry(2, one(c)),
            steps: &[Tick(0.0, 'R', "A", ""), Tick(1.0, 'R', "A", ""), Tick(2.0, 'S', "A", "")],
        },
        Row {
            scenario: "after n retries the failure passes through",
            scripts: &["FFF"],
            shape: |c| retry(2, one(c)),
            steps: &[Tick(0.0, 'R', "A", ""), Tick(1.0, 'R', "A", ""), Tick(2.0, 'F', "A", "")],
        },
        Row {
            scenario: "the count resets when the decorator finishes",
            scripts: &["FFFS"],
            shape: |c| retry(1, one(c)),
            steps: &[
                Tick(0.0, 'R', "A", ""),
                Tick(1.0, 'F', "A", ""),
                Tick(2.0, 'R', "A", ""),
                Tick(3.0, 'S', "A", ""),
            ],
        },
        Row {
            scenario: "running is not a failure",
            scripts: &["RFRS"],
            shape: |c| retry(1, one(c)),
            steps: &[
                Tick(0.0, 'R', "A", ""),
                Tick(1.0, 'R', "A", ""),
                Tick(2.0, 'R', "A", ""),
                Tick(3.0, 'S', "A", ""),
            ],
        },
        Row {
            scenario: "halting resets the count (the idle child is not halted)",
            scripts: &["FF"],
            shape: |c| retry(1, one(c)),
            steps: &[Tick(0.0, 'R', "A", ""), Halt(""), Tick(1.0, 'R', "A", "")],
        },
        Row {
            scenario: "zero retries: the failure passes through",
            scripts: &["F"],
            shape: |c| retry(0, one(c)),
            steps: &[Tick(0.0, 'F', "A", "")],
        },
    ]);
}

#[test]
fn rate_limit_decorator() {
    run(&[
        Row {
            scenario: "between ticks of the child the last status is returned, terminal too",
            scripts: &["RRSSF"],
            shape: |c| rate_limit(secs(1.0), one(c)),
            steps: &[
                Tick(0.0, 'R', "A", ""),
                Tick(0.5, 'R', "", ""),
                Tick(1.0, 'S', "A", ""),
                Tick(1.2, 'S', "", ""),
                Tick(2.0, 'F', "A", ""),
            ],
        },
        Row {
            scenario: "a cached failure is returned until the interval has passed",
            scripts: &["FFS"],
            shape: |c| rate_limit(secs(1.0), one(c)),
            steps: &[Tick(0.0, 'F', "A", ""), Tick(0.9, 'F', "", ""), Tick(1.0, 'S', "A", "")],
        },
        Row {
            scenario: "halting clears the window",
            scripts: &["RR"],
            shape: |c| rate_limit(secs(1.0), one(c)),
            steps: &[Tick(0.0, 'R', "A", ""), Halt("A"), Tick(0.5, 'R', "A", "")],
        },
    ]);
}

#[test]
fn status_mapping_decorators() {
    run(&[
        Row {
            scenario: "inverter swaps success and failure",
            scripts: &["SFR"],
            shape: |c| inverter(one(c)),
            steps: &[Tick(0.0, 'F', "A", ""), Tick(1.0, 'S', "A", ""), Tick(2.0, 'R', "A", "")],
        },
        Row {
            scenario: "force_success",
            scripts: &["SFR"],
            shape: |c| force_success(one(c)),
            steps: &[Tick(0.0, 'S', "A", ""), Tick(1.0, 'S', "A", ""), Tick(2.0, 'R', "A", "")],
        },
        Row {
            scenario: "force_failure",
            scripts: &["SFR"],
            shape: |c| force_failure(one(c)),
            steps: &[Tick(0.0, 'F', "A", ""), Tick(1.0, 'F', "A", ""), Tick(2.0, 'R', "A", "")],
        },
    ]);
}

#[test]
fn halting_running_subtrees() {
    run(&[
        Row {
            scenario: "every running descendant is halted once, innermost first",
            scripts: &["SS", "RR", "FF", "RR", "SS", "RR"],
            shape: |c| {
                let [a, b, c, d, e, f]: [Subtree<Log>; 6] =
                    c.try_into().unwrap_or_else(|_| panic!("six leaves"));
                parallel(
                    "P",
                    Threshold::All,
                    Threshold::Any,
                    [
                        probe("p1", sequence("S", [a, probe("p2", b)])),
                        probe(
                            "p3",
                            reactive_selector("Sel", [c, probe("p4", timeout(secs(10.0), d))]),
                        ),
                        probe("p5", e),
                        probe("p6", f),
                    ],
                )
            },
            steps: &[
                Tick(0.0, 'R', "A B C D E F", ""),
                Halt("B p2 p1 D p4 p3 F p6"),
                Halt(""),
                // Everything starts from scratch, the memory sequence at its first child.
                Tick(1.0, 'R', "A B C D E F", ""),
            ],
        },
        Row {
            scenario: "a reactive preemption halts the whole running subtree, innermost first",
            scripts: &["SF", "RR"],
            shape: |c| {
                let [a, b]: [Subtree<Log>; 2] = c.try_into().unwrap_or_else(|_| panic!("two"));
                reactive_sequence("R", [a, probe("p", sequence("S", [probe("q", b)]))])
            },
            steps: &[Tick(0.0, 'R', "A B", ""), Tick(1.0, 'F', "A", "B q p"), Halt("")],
        },
        Row {
            scenario: "halting a finished tree does nothing",
            scripts: &["S"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'S', "A", ""), Halt("")],
        },
        Row {
            scenario: "a halted memory sequence restarts from its first child",
            scripts: &["SS", "RR"],
            shape: |c| sequence("seq", c),
            steps: &[Tick(0.0, 'R', "A B", ""), Halt("B"), Tick(1.0, 'R', "A B", "")],
        },
        Row {
            scenario: "a node that finishes leaving children running: the engine halts them",
            scripts: &["R", "S"],
            shape: |c| leaf(Sloppy { children: c }),
            steps: &[Tick(0.0, 'S', "A B", "A"), Halt("")],
        },
    ]);
}

#[test]
fn active_path() {
    use Threshold::{All, Any};
    run(&[
        Row {
            scenario: "running nodes from the root down; the last ticked after a preemption",
            scripts: &["SS", "FS", "RR"],
            shape: |c| {
                let [a, b, c]: [Subtree<Log>; 3] =
                    c.try_into().unwrap_or_else(|_| panic!("three leaves"));
                sequence("Goalie playing", [a, reactive_selector("Goal covering", [b, c])])
            },
            steps: &[
                Path("Goalie playing"),
                Tick(0.0, 'R', "A B C", ""),
                Path("Goalie playing/Goal covering/C"),
                Tick(1.0, 'S', "B", "C"),
                Path("Goalie playing/Goal covering/B"),
            ],
        },
        Row {
            scenario: "a running child is preferred to a later finished one",
            scripts: &["R", "S"],
            shape: |c| parallel("P", All, Any, c),
            steps: &[Tick(0.0, 'R', "A B", ""), Path("P/A")],
        },
        Row {
            scenario: "after a halt the path shows what was running",
            scripts: &["R"],
            shape: |c| sequence("S", c),
            steps: &[Tick(0.0, 'R', "A", ""), Halt("A"), Path("S/A")],
        },
        Row {
            scenario: "decorators appear under their name, or a given one",
            scripts: &["F"],
            shape: |c| sequence("S", [retry(1, timeout(secs(1.0), one(c))).named("persist")]),
            steps: &[Tick(0.0, 'R', "A", ""), Path("S/persist/Timeout/A")],
        },
    ]);
}

#[test]
fn start_is_called_before_the_first_tick_of_each_run() {
    // (operation, leaves started by it): A runs R R S R R, B always succeeds.
    let steps =
        [("tick", "A"), ("tick", ""), ("tick", "B"), ("tick", "A"), ("halt", ""), ("tick", "A")];
    let mut tree = Tree::new(sequence("seq", [scripted("A", "RRSRR"), scripted("B", "SSSSS")]));
    let mut log = Log::default();
    for (i, (operation, started)) in steps.into_iter().enumerate() {
        log.events.clear();
        if operation == "halt" {
            tree.halt(&mut log);
        } else {
            let now = at(log.tick as f64);
            tree.tick(&mut log, now);
            log.tick += 1;
        }
        assert_eq!(log.names(Event::Start), started, "step {i} ({operation})");
    }
}

#[test]
fn action_halt_closure_runs_only_when_interrupted() {
    #[derive(Default)]
    struct Counts {
        ticks: u32,
        halts: u32,
        done: bool,
    }
    let walk = || {
        action_with_halt(
            "walk",
            |c: &mut Counts, _| {
                c.ticks += 1;
                if c.done { Status::Success } else { Status::Running }
            },
            |c: &mut Counts| c.halts += 1,
        )
    };
    let mut tree = Tree::new(walk());
    let mut counts = Counts::default();
    tree.tick(&mut counts, at(0.0));
    tree.halt(&mut counts);
    tree.halt(&mut counts);
    assert_eq!((counts.ticks, counts.halts), (1, 1));
    counts.done = true;
    assert_eq!(tree.tick(&mut counts, at(1.0)), Status::Success);
    tree.halt(&mut counts);
    assert_eq!((counts.ticks, counts.halts), (2, 1));
    assert_eq!(tree.status(), Some(Status::Success));
}

// =============================================================================================
// Hierarchical state machines

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Player {
    Playing,
    Attack,
    Approach,
    Kick,
    Defend,
    Fallen,
}

/// The context of the state-machine tables: flags the guards and behaviors read, and what the
/// hooks and bodies did.
#[derive(Default)]
struct Robot {
    flags: BTreeSet<&'static str>,
    events: Vec<String>,
}

impl Robot {
    fn on(&self, flag: &str) -> bool {
        self.flags.contains(flag)
    }
}

/// ```text
/// Playing (initial Attack)      fallen -> Fallen
///   Attack (initial Approach)   ball lost -> Defend; reset -> Attack
///     Approach  tree "approach ball"/walk (succeeds when arrived)
///                               body succeeded -> Kick
///     Kick      behavior (succeeds when kicked)
///                               body succeeded -> Approach; kick again -> Kick
///   Defend      behavior        !ball lost -> Attack
/// Fallen        behavior        !fallen -> Playing
/// ```
fn player() -> StateMachine<Player, Robot> {
    use Player::*;
    fn hooks(state: State<Player, Robot>, name: &'static str) -> State<Player, Robot> {
        state
            .on_enter(move |r: &mut Robot, _| r.events.push(format!("enter {name}")))
            .on_exit(move |r: &mut Robot, _| r.events.push(format!("exit {name}")))
    }
    let log_behavior = |name: &'static str, done: Option<&'static str>| {
        move |r: &mut Robot, _: Time| {
            r.events.push(format!("tick {name}"));
            if done.is_some_and(|flag| r.on(flag)) { Status::Success } else { Status::Running }
        }
    };
    let walk = action_with_halt(
        "walk",
        |r: &mut Robot, _| {
            r.events.push("tick walk".into());
            if r.on("arrived") { Status::Success } else { Status::Running }
        },
        |r: &mut Robot| r.events.push("halt walk".into()),
    );
    let built = StateMachine::builder()
        .initial(Playing)
        .state(
            hooks(State::new(Playing), "Playing")
                .initial_child(Attack)
                .transition(|r: &Robot, _| r.on("fallen"), Fallen),
        )
        .state(
            hooks(State::new(Attack), "Attack")
                .parent(Playing)
                .initial_child(Approach)
                .transition(|r: &Robot, _| r.on("ball lost"), Defend)
                .transition(|r: &Robot, _| r.on("reset"), Attack),
        )
        .state(
            hooks(State::new(Approach), "Approach")
                .parent(Attack)
                .tree(Tree::new(sequence("approach ball", [walk])))
                .transition(|_, status| status == Status::Success, Kick),
        )
        .state(
            hooks(State::new(Kick), "Kick")
                .parent(Attack)
                .behavior(log_behavior("Kick", Some("kicked")))
                .transition(|_, status| status == Status::Success, Approach)
                .transition(|r: &Robot, _| r.on("kick again"), Kick),
        )
        .state(
            hooks(State::new(Defend), "Defend")
                .parent(Playing)
                .behavior(log_behavior("Defend", None))
                .transition(|r: &Robot, _| !r.on("ball lost"), Attack),
        )
        .state(
            hooks(State::new(Fallen), "Fallen")
                .behavior(log_behavior("Fallen", None))
                .transition(|r: &Robot, _| !r.on("fallen"), Playing),
        )
        .build();
    match built {
        Ok(machine) => machine,
        Err(error) => panic!("the test machine is valid: {error}"),
    }
}

const START: (&str, &[&str], &str) = (
    "",
    &["enter Playing", "enter Attack", "enter Approach", "tick walk"],
    "Playing/Attack/Approach/approach ball/walk",
);
const WALKING: &str = "Playing/Attack/Approach/approach ball/walk";

/// A state-machine scenario: each step changes flags (`+flag`, `-flag`, comma-separated; the
/// word `halt` halts the machine instead of ticking it), then expects exactly these hook and
/// body events, in order, and this active path.
struct MachineRow {
    scenario: &'static str,
    steps: &'static [(&'static str, &'static [&'static str], &'static str)],
}

fn run_machines(rows: &[MachineRow]) {
    let mut failures = Vec::new();
    for row in rows {
        let mut machine = player();
        let mut robot = Robot::default();
        for (i, &(changes, events, path)) in row.steps.iter().enumerate() {
            robot.events.clear();
            let now = at(i as f64 * 0.5);
            if changes == "halt" {
                machine.halt(&mut robot, now);
            } else {
                for change in changes.split(',').map(str::trim).filter(|c| !c.is_empty()) {
                    match change.split_at(1) {
                        ("+", flag) => robot.flags.insert(flag_name(flag)),
                        ("-", flag) => robot.flags.remove(flag),
                        _ => panic!("bad change {change:?}"),
                    };
                }
                machine.tick(&mut robot, now);
            }
            let actual_path = machine.active_path();
            if robot.events != events || actual_path != path {
                failures.push(format!(
                    "{}: step {i} ({changes:?}): events {:?}, path {actual_path:?}",
                    row.scenario, robot.events
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{} failing rows:\n{}", failures.len(), failures.join("\n"));
}

fn flag_name(flag: &str) -> &'static str {
    ["fallen", "ball lost", "reset", "arrived", "kicked", "kick again"]
        .into_iter()
        .find(|known| *known == flag)
        .unwrap_or_else(|| panic!("unknown flag {flag:?}"))
}

// One table, over 150 lines: each row is a rule of docs/tick-semantics.md, and the rules read
// in the document's order.
#[test]
fn state_machine_transitions() {
    run_machines(&[
        MachineRow {
            scenario: "start: enter the initial state, descend through initial children",
            steps: &[START, ("", &["tick walk"], WALKING)],
        },
        MachineRow {
            scenario: "guards see the body's status on the next tick; a finished tree is not halted",
            steps: &[
                START,
                ("+arrived", &["tick walk"], WALKING),
                ("-arrived", &["exit Approach", "enter Kick", "tick Kick"], "Playing/Attack/Kick"),
            ],
        },
        MachineRow {
            scenario: "outer before inner: a parent's guard preempts its children's",
            steps: &[
                START,
                ("+arrived", &["tick walk"], WALKING),
                (
                    "+fallen, +ball lost",
                    &[
                        "exit Approach",
                        "exit Attack",
                        "exit Playing",
                        "enter Fallen",
                        "tick Fallen",
                    ],
                    "Fallen",
                ),
            ],
        },
        MachineRow {
            scenario: "exiting halts the running tree before the on-exit hooks, innermost first",
            steps: &[
                START,
                (
                    "+fallen",
                    &[
                        "halt walk",
                        "exit Approach",
                        "exit Attack",
                        "exit Playing",
                        "enter Fallen",
                        "tick Fallen",
                    ],
                    "Fallen",
                ),
                (
                    "-fallen",
                    &[
                        "exit Fallen",
                        "enter Playing",
                        "enter Attack",
                        "enter Approach",
                        "tick walk",
                    ],
                    WALKING,
                ),
            ],
        },
        MachineRow {
            scenario: "exit up to and enter below the common ancestor (Playing stays)",
            steps: &[
                START,
                (
                    "+ball lost",
                    &["halt walk", "exit Approach", "exit Attack", "enter Defend", "tick Defend"],
                    "Playing/Defend",
                ),
                (
                    "-ball lost",
                    &["exit Defend", "enter Attack", "enter Approach", "tick walk"],
                    WALKING,
                ),
            ],
        },
        MachineRow {
            scenario: "a self-transition exits and re-enters the state",
            steps: &[
                START,
                ("+arrived", &["tick walk"], WALKING),
                ("-arrived", &["exit Approach", "enter Kick", "tick Kick"], "Playing/Attack/Kick"),
                ("+kick again", &["exit Kick", "enter Kick", "tick Kick"], "Playing/Attack/Kick"),
                ("-kick again", &["tick Kick"], "Playing/Attack/Kick"),
            ],
        },
        MachineRow {
            scenario: "a transition to an active ancestor re-enters it and its initial leaf",
            steps: &[
                START,
                (
                    "+reset",
                    &[
                        "halt walk",
                        "exit Approach",
                        "exit Attack",
                        "enter Attack",
                        "enter Approach",
                        "tick walk",
                    ],
                    WALKING,
                ),
            ],
        },
        MachineRow {
            scenario: "one transition per tick: a guard true in the new state fires next tick",
            steps: &[
                START,
                (
                    "+fallen",
                    &[
                        "halt walk",
                        "exit Approach",
                        "exit Attack",
                        "exit Playing",
                        "enter Fallen",
                        "tick Fallen",
                    ],
                    "Fallen",
                ),
                (
                    "-fallen, +ball lost",
                    &[
                        "exit Fallen",
                        "enter Playing",
                        "enter Attack",
                        "enter Approach",
                        "tick walk",
                    ],
                    WALKING,
                ),
                (
                    "",
                    &["halt walk", "exit Approach", "exit Attack", "enter Defend", "tick Defend"],
                    "Playing/Defend",
                ),
            ],
        },
        MachineRow {
            scenario: "within a state, transitions fire in declaration order",
            steps: &[
                START,
                ("+arrived", &["tick walk"], WALKING),
                ("-arrived", &["exit Approach", "enter Kick", "tick Kick"], "Playing/Attack/Kick"),
                ("+kicked", &["tick Kick"], "Playing/Attack/Kick"),
                ("-kicked, +kick again", &["exit Kick", "enter Approach", "tick walk"], WALKING),
            ],
        },
        MachineRow {
            scenario: "halt exits every active state innermost first; the next tick restarts",
            steps: &[
                START,
                ("halt", &["halt walk", "exit Approach", "exit Attack", "exit Playing"], ""),
                ("halt", &[], ""),
                START,
            ],
        },
    ]);
}

#[test]
fn tick_results_and_entry_times() {
    let mut machine = player();
    let mut robot = Robot::default();
    let first = machine.tick(&mut robot, at(1.0));
    assert!(first.started);
    assert_eq!(first.fired, None);
    assert_eq!(first.status, Status::Running);
    robot.flags.insert("ball lost");
    let second = machine.tick(&mut robot, at(2.0));
    assert!(!second.started);
    assert_eq!(
        second.fired,
        Some(Fired { source: Player::Attack, target: Player::Defend }),
        "the source is the state that declared the transition"
    );
    assert_eq!(machine.entered_at(Player::Playing), Some(at(1.0)));
    assert_eq!(machine.entered_at(Player::Defend), Some(at(2.0)));
    assert_eq!(machine.entered_at(Player::Attack), None);
    assert!(machine.is_in(Player::Playing));
    assert!(!machine.is_in(Player::Attack));
    assert_eq!(machine.active_states().collect::<Vec<_>>(), [Player::Playing, Player::Defend]);
    assert_eq!(machine.last_status(), Some(Status::Running));
    assert!(machine.tree(Player::Approach).is_some_and(|tree| !tree.is_running()));
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum V {
    A,
    B,
    C,
}

#[test]
fn builder_validation() {
    use V::*;
    type Built = Result<StateMachine<V, ()>, BuildError<V>>;
    let s = State::<V, ()>::new;
    let rows: Vec<(&str, Built, Option<BuildError<V>>)> = vec![
        ("valid", StateMachine::builder().initial(A).state(s(A)).build(), None),
        (
            "duplicate state",
            StateMachine::builder().initial(A).state(s(A)).state(s(B)).state(s(A)).build(),
            Some(BuildError::DuplicateState(A)),
        ),
        (
            "unknown parent",
            StateMachine::builder().initial(A).state(s(A)).state(s(B).parent(C)).build(),
            Some(BuildError::UnknownParent { state: B, parent: C }),
        ),
        (
            "a state that is its own parent",
            StateMachine::builder().initial(A).state(s(A).parent(A)).build(),
            Some(BuildError::HierarchyCycle(A)),
        ),
        (
            "a two-state cycle, reached from a state outside it",
            StateMachine::builder()
                .initial(C)
                .state(s(C).parent(A))
                .state(s(A).parent(B).initial_child(C))
                .state(s(B).parent(A).initial_child(A))
                .build(),
            Some(BuildError::HierarchyCycle(A)),
        ),
        (
            "initial child that is a top-level state",
            StateMachine::builder().initial(A).state(s(A).initial_child(B)).state(s(B)).build(),
            Some(BuildError::InitialNotChild { state: A, initial: B }),
        ),
        (
            "initial child that is a grandchild",
            StateMachine::builder()
                .initial(A)
                .state(s(A).initial_child(C))
                .state(s(B).parent(A).initial_child(C))
                .state(s(C).parent(B))
                .build(),
            Some(BuildError::InitialNotChild { state: A, initial: C }),
        ),
        (
            "initial child that is not defined",
            StateMachine::builder().initial(A).state(s(A).initial_child(C)).build(),
            Some(BuildError::InitialNotChild { state: A, initial: C }),
        ),
        (
            "composite without initial child",
            StateMachine::builder().initial(A).state(s(A)).state(s(B).parent(A)).build(),
            Some(BuildError::MissingInitialChild(A)),
        ),
        (
            "body on a composite state",
            StateMachine::builder()
                .initial(A)
                .state(s(A).initial_child(B).behavior(|_, _| Status::Running))
                .state(s(B).parent(A))
                .build(),
            Some(BuildError::BodyOnComposite(A)),
        ),
        (
            "unknown transition target",
            StateMachine::builder()
                .initial(A)
                .state(s(A))
                .state(s(B).transition(|_, _| true, C))
                .build(),
            Some(BuildError::UnknownTarget { state: B, target: C }),
        ),
        (
            "no initial state",
            StateMachine::builder().state(s(A)).build(),
            Some(BuildError::NoInitialState),
        ),
        (
            "unknown initial state",
            StateMachine::builder().initial(C).state(s(A)).build(),
            Some(BuildError::UnknownInitialState(C)),
        ),
    ];
    let mut failures = Vec::new();
    for (scenario, built, expected) in rows {
        let actual = built.err();
        if actual != expected {
            failures.push(format!("{scenario}: expected {expected:?}, got {actual:?}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert_eq!(
        BuildError::InitialNotChild { state: A, initial: B }.to_string(),
        "state A has initial child B, which is not one of its children"
    );
}

#[test]
fn a_nested_initial_state_is_entered_from_the_top() {
    use V::*;
    let log = |name: &'static str| move |events: &mut Vec<&'static str>, _| events.push(name);
    let built = StateMachine::builder()
        .initial(B)
        .state(State::new(A).initial_child(C).on_enter(log("enter A")))
        .state(State::new(B).parent(A).on_enter(log("enter B")))
        .state(State::new(C).parent(A).on_enter(log("enter C")))
        .build();
    let Ok(mut machine) = built else { panic!("valid machine") };
    let mut events = Vec::new();
    machine.tick(&mut events, at(0.0));
    assert_eq!(events, ["enter A", "enter B"]);
    assert_eq!(machine.active_path(), "A/B");
}

#[test]
fn engines_can_move_to_a_module_thread() {
    fn assert_send<T: Send>() {}
    assert_send::<Tree<Robot>>();
    assert_send::<StateMachine<Player, Robot>>();
}

// =============================================================================================
// No allocation per tick in the steady state

mod counting {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    thread_local! {
        static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    }

    /// The system allocator, counting allocations per thread (tests run in parallel).
    pub struct Counting;

    // A global allocator can only be written with `unsafe`; this one forwards every call to the
    // system allocator unchanged and only counts.
    #[allow(unsafe_code)]
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
            // SAFETY: same contract as ours.
            unsafe { System.alloc(layout) }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: same contract as ours.
            unsafe { System.dealloc(ptr, layout) }
        }

        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
            // SAFETY: same contract as ours.
            unsafe { System.realloc(ptr, layout, new_size) }
        }
    }

    pub fn allocations() -> u64 {
        ALLOCATIONS.with(Cell::get)
    }
}

#[global_allocator]
static ALLOCATOR: counting::Counting = counting::Counting;

#[test]
fn steady_state_ticks_do_not_allocate() {
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    enum Loop {
        Top,
        Walk,
        Kick,
    }
    #[derive(Default)]
    struct Counters {
        ticks: u64,
        hooks: u64,
    }
    let counted = |state: State<Loop, Counters>| {
        state.on_enter(|c: &mut Counters, _| c.hooks += 1).on_exit(|c: &mut Counters, _| {
            c.hooks += 1;
        })
    };
    let walk_tree = Tree::new(reactive_sequence(
        "walk",
        [
            condition("standing", |_: &Counters| true),
            timeout(
                secs(10.0),
                action("step", |c: &mut Counters, _| {
                    c.ticks += 1;
                    if c.ticks.is_multiple_of(3) { Status::Success } else { Status::Running }
                }),
            ),
        ],
    ));
    let built = StateMachine::builder()
        .initial(Loop::Top)
        .state(
            counted(State::new(Loop::Top))
                .initial_child(Loop::Walk)
                .transition(|c: &Counters, _| c.ticks == u64::MAX, Loop::Top),
        )
        .state(
            counted(State::new(Loop::Walk))
                .parent(Loop::Top)
                .tree(walk_tree)
                .transition(|_, s| s == Status::Success, Loop::Kick),
        )
        .state(
            counted(State::new(Loop::Kick))
                .parent(Loop::Top)
                .behavior(|c: &mut Counters, _| {
                    c.ticks += 1;
                    Status::Success
                })
                .transition(|_, s| s == Status::Success, Loop::Walk),
        )
        .build();
    let Ok(mut machine) = built else { panic!("valid machine") };
    let mut counters = Counters::default();
    let mut path = String::with_capacity(256);
    let mut now = Time::ZERO;
    let mut cycle = |machine: &mut StateMachine<Loop, Counters>, counters: &mut Counters| {
        now += Duration::from_millis(10);
        machine.tick(counters, now);
        path.clear();
        let _ = machine.write_active_path(&mut path);
    };
    for _ in 0..10 {
        cycle(&mut machine, &mut counters);
    }
    let hooks_before = counters.hooks;
    let before = counting::allocations();
    for _ in 0..1000 {
        cycle(&mut machine, &mut counters);
    }
    let allocated = counting::allocations() - before;
    assert!(counters.hooks - hooks_before > 500, "the loop must exercise transitions");
    assert_eq!(allocated, 0, "allocations in 1000 steady-state ticks");
}

//! The three connection policies, tabulated: what a reader sees after a sequence of sends and
//! takes, and what the connection counts.

use strata_runtime::{Arrival, Connection, ConnectionCounters, ModuleId, Package, Policy, Time};

#[derive(Clone, Copy, Debug)]
enum Op {
    Send(i64),
    /// Take the oldest pending package.
    Take,
    /// Take the newest; older ones are consumed with it.
    TakeNewest,
    Drain,
}

struct Row {
    name: &'static str,
    policy: fn() -> Policy<i64>,
    ops: &'static [Op],
    /// Values the reader saw, in order.
    seen: &'static [i64],
    /// What each send reported.
    arrivals: &'static [Arrival],
    counters: ConnectionCounters,
}

fn counters(
    received: u64,
    delivered: u64,
    overwritten: u64,
    dropped: u64,
    merged: u64,
) -> ConnectionCounters {
    ConnectionCounters { received, delivered, overwritten, dropped, merged }
}

fn run(row: &Row) -> (Vec<i64>, Vec<Arrival>, ConnectionCounters, Vec<u64>) {
    let mut connection = Connection::new((row.policy)());
    let mut seen = Vec::new();
    let mut arrivals = Vec::new();
    let mut seqs = Vec::new();
    let mut seq = 0;
    for op in row.ops {
        match *op {
            Op::Send(v) => {
                arrivals.push(connection.push(Package::new(
                    v,
                    Time::from_nanos(seq * 10),
                    seq,
                    ModuleId(0),
                )));
                seq += 1;
            }
            Op::Take => {
                if let Some(p) = connection.take() {
                    seen.push(p.value);
                    seqs.push(p.seq);
                }
            }
            Op::TakeNewest => {
                if let Some(p) = connection.take_newest() {
                    seen.push(p.value);
                    seqs.push(p.seq);
                }
            }
            Op::Drain => {
                for p in connection.drain() {
                    seen.push(p.value);
                    seqs.push(p.seq);
                }
            }
        }
    }
    (seen, arrivals, connection.counters(), seqs)
}

use Arrival::*;
use Op::*;

fn sum() -> Policy<i64> {
    Policy::merge(|pending: &mut i64, new| *pending += new)
}

#[test]
fn policy_table() {
    let rows = [
        Row {
            name: "latest: a pending package is overwritten by the newest",
            policy: || Policy::Latest,
            ops: &[Send(1), Send(2), Send(3), Take],
            seen: &[3],
            arrivals: &[First, Overwrote, Overwrote],
            counters: counters(3, 1, 2, 0, 0),
        },
        Row {
            name: "latest: nothing pending, nothing seen",
            policy: || Policy::Latest,
            ops: &[Send(1), Take, Take, Send(2), Take],
            seen: &[1, 2],
            arrivals: &[First, First],
            counters: counters(2, 2, 0, 0, 0),
        },
        Row {
            name: "queue: every package arrives in order",
            policy: || Policy::queue(8),
            ops: &[Send(1), Send(2), Send(3), Take, Drain],
            seen: &[1, 2, 3],
            arrivals: &[First, Queued, Queued],
            counters: counters(3, 3, 0, 0, 0),
        },
        Row {
            name: "queue: overflow drops the oldest and is counted, the sender never blocks",
            policy: || Policy::queue(2),
            ops: &[Send(1), Send(2), Send(3), Send(4), Drain],
            seen: &[3, 4],
            arrivals: &[First, Queued, DroppedOldest, DroppedOldest],
            counters: counters(4, 2, 0, 2, 0),
        },
        Row {
            name: "queue: take-newest consumes the older ones",
            policy: || Policy::queue(8),
            ops: &[Send(1), Send(2), Send(3), TakeNewest, Take],
            seen: &[3],
            arrivals: &[First, Queued, Queued],
            counters: counters(3, 3, 0, 0, 0),
        },
        Row {
            name: "merge: pending packages are re-packaged into one (summed)",
            policy: sum,
            ops: &[Send(1), Send(2), Send(4), Take, Send(8), Take],
            seen: &[7, 8],
            arrivals: &[First, Merged, Merged, First],
            counters: counters(4, 2, 0, 0, 2),
        },
        Row {
            name: "merge: a lone package passes unchanged",
            policy: sum,
            ops: &[Send(5), Drain],
            seen: &[5],
            arrivals: &[First],
            counters: counters(1, 1, 0, 0, 0),
        },
    ];
    for row in &rows {
        let (seen, arrivals, counters, _) = run(row);
        assert_eq!(seen, row.seen, "{}: values seen", row.name);
        assert_eq!(arrivals, row.arrivals, "{}: arrivals", row.name);
        assert_eq!(counters, row.counters, "{}: counters", row.name);
    }
}

#[test]
fn a_merged_package_carries_the_newest_stamp_and_sequence_number() {
    let mut connection = Connection::new(sum());
    for seq in 0..3 {
        connection.push(Package::new(1, Time::from_nanos(100 + seq), seq, ModuleId(4)));
    }
    let package = connection.take().expect("one merged package");
    assert_eq!(package.value, 3);
    assert_eq!(package.stamp, Time::from_nanos(102));
    assert_eq!(package.seq, 2);
}

#[test]
fn gaps_in_sequence_numbers_reveal_overwritten_packages() {
    let row = Row {
        name: "latest with gaps",
        policy: || Policy::Latest,
        ops: &[Send(10), Take, Send(11), Send(12), Take],
        seen: &[10, 12],
        arrivals: &[First, First, Overwrote],
        counters: counters(3, 2, 1, 0, 0),
    };
    let (_, _, _, seqs) = run(&row);
    assert_eq!(seqs, vec![0, 2]);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever is sent, a queue delivers a suffix of it, in order, and counts the rest.
        #[test]
        fn queue_delivers_an_ordered_suffix(values in proptest::collection::vec(any::<i64>(), 0..64), capacity in 1usize..16) {
            let mut connection = Connection::new(Policy::queue(capacity));
            for (i, v) in values.iter().enumerate() {
                connection.push(Package::new(*v, Time::ZERO, i as u64, ModuleId(0)));
            }
            let seen: Vec<i64> = connection.drain().into_iter().map(|p| p.value).collect();
            let keep = values.len().min(capacity);
            prop_assert_eq!(&seen[..], &values[values.len() - keep..]);
            prop_assert_eq!(connection.counters().dropped as usize, values.len() - keep);
        }

        /// Merging with a sum never loses a contribution, however sends and takes interleave.
        #[test]
        fn merge_conserves_the_total(ops in proptest::collection::vec(prop_oneof![(-1000i64..1000).prop_map(Some), Just(None)], 0..64)) {
            let mut connection = Connection::new(sum());
            let mut sent = 0i64;
            let mut received = 0i64;
            for (i, op) in ops.iter().enumerate() {
                match op {
                    Some(v) => { sent += v; connection.push(Package::new(*v, Time::ZERO, i as u64, ModuleId(0))); }
                    None => { if let Some(p) = connection.take() { received += p.value; } }
                }
            }
            received += connection.drain().iter().map(|p| p.value).sum::<i64>();
            prop_assert_eq!(sent, received);
        }
    }
}

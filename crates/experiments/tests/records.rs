//! Job records (`strata_experiments::records`): a sweep's shards merged give the report of one
//! process; records of another sweep, broken or missing records are refused by name.

use std::path::{Path, PathBuf};

use strata_experiments::records::{RecordMode, Records, decode_for, record_path};
use strata_experiments::{Options, RECORDABLE, goal_covering, plan, run};

/// Two short paths, two runs: four jobs of a few simulated seconds.
const SCENARIO: &str = r#"
field = "spl"
noise = "default"
runs = 2
ball_speed = 0.4
deliberative_hz = [1.0]
reactive_hz = 57.0
warmup = 1.0
settle = 0.5
sample_period = 0.05
keeper_start = [-2.55, 0.0, 0.0]
reference = "value-function"
target_pose_error = 0.10

[[methods]]
name = "value-function"
team = "full"

[[trajectories]]
name = "across"
waypoints = [[-1.0, -1.0], [-1.0, 1.0]]

[[trajectories]]
name = "toward"
waypoints = [[0.0, 0.5], [-1.5, 0.0]]
"#;

const JOBS: usize = 4;

/// A fresh directory for one test, with the scenario file in it.
fn setup(test: &str) -> (PathBuf, PathBuf) {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("records").join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("test directory");
    let scenario = dir.join("scenario.toml");
    std::fs::write(&scenario, SCENARIO).expect("scenario");
    (dir, scenario)
}

fn options(scenario: &Path, out: PathBuf, records: Option<Records>) -> Options {
    Options {
        scenario: Some(scenario.to_path_buf()),
        out: Some(out),
        threads: 2,
        records,
        ..Options::default()
    }
}

fn records(dir: &Path, mode: RecordMode) -> Option<Records> {
    Some(Records { dir: dir.to_path_buf(), mode })
}

fn shard(scenario: &Path, dir: &Path, only: &[usize]) -> serde_json::Value {
    let mode = RecordMode::Run { only: Some(only.to_vec()) };
    let outcome =
        run(goal_covering::NAME, &options(scenario, dir.join("unused"), records(dir, mode)))
            .expect("shard runs");
    outcome.summary
}

#[test]
fn merged_shards_give_the_summary_and_runs_of_one_process() {
    let (dir, scenario) = setup("merge");
    let whole = run(goal_covering::NAME, &options(&scenario, dir.join("whole"), None))
        .expect("single-process run");

    let rec = dir.join("records");
    let opts = options(&scenario, dir.join("merged"), None);
    assert_eq!(plan(goal_covering::NAME, &opts, &rec).expect("plan"), JOBS);
    let first = shard(&scenario, &rec, &[0, 2]);
    assert_eq!(first["written"], serde_json::json!([0, 2]));
    // Resume: the records there are finished jobs, not run again.
    let second = shard(&scenario, &rec, &[2, 1, 3]);
    assert_eq!(second["written"], serde_json::json!([1, 3]));
    assert_eq!(second["skipped"], serde_json::json!([2]));
    // A shard writes its records and no report.
    assert!(!dir.join("unused").exists());

    let merged = run(
        goal_covering::NAME,
        &options(&scenario, dir.join("merged"), records(&rec, RecordMode::Merge)),
    )
    .expect("merge");
    assert_eq!(merged.summary, whole.summary);
    for file in ["summary.json", "runs.csv"] {
        let a = std::fs::read(dir.join("whole").join(file)).expect("whole");
        let b = std::fs::read(dir.join("merged").join(file)).expect("merged");
        assert!(a == b, "{file} differs between the single-process run and the merge");
    }
    assert!(dir.join("merged/report.md").exists());
}

#[test]
fn records_of_another_sweep_are_refused() {
    let (dir, scenario) = setup("manifest");
    let rec = dir.join("records");
    let opts = options(&scenario, dir.join("out"), None);
    plan(goal_covering::NAME, &opts, &rec).expect("plan");
    let other_seed = Options { seed: 7, ..opts.clone() };
    let err = plan(goal_covering::NAME, &other_seed, &rec).expect_err("another seed");
    let text = format!("{err:#}");
    assert!(text.contains("another sweep") && text.contains("seed"), "{text}");
    assert!(text.contains("manifest.json"), "{text}");

    let other = dir.join("other.toml");
    std::fs::write(&other, SCENARIO.replace("runs = 2", "runs = 1")).expect("scenario");
    let err = plan(goal_covering::NAME, &options(&other, dir.join("out"), None), &rec)
        .expect_err("another scenario");
    assert!(format!("{err:#}").contains("scenario hash"), "{err:#}");
}

#[test]
fn a_missing_truncated_or_garbage_record_is_an_error_naming_the_file() {
    let (dir, scenario) = setup("broken");
    let rec = dir.join("records");
    shard(&scenario, &rec, &[0, 1, 2]);
    let merge = || {
        let opts = options(&scenario, dir.join("merged"), records(&rec, RecordMode::Merge));
        format!("{:#}", run(goal_covering::NAME, &opts).expect_err("merge fails"))
    };
    let missing = record_path(&rec, 3);
    let text = merge();
    assert!(text.contains("missing record") && text.contains(&missing.display().to_string()));

    let good = std::fs::read(record_path(&rec, 0)).expect("record");
    std::fs::write(&missing, &good[..good.len() / 2]).expect("truncated");
    let text = merge();
    assert!(text.contains(&missing.display().to_string()) && text.contains("truncated"), "{text}");

    std::fs::write(&missing, b"{\"not\": \"a record\"}").expect("garbage");
    let text = merge();
    assert!(text.contains(&missing.display().to_string()), "{text}");

    // Job 0's record renamed to job 3's.
    std::fs::write(&missing, &good).expect("copy");
    let text = merge();
    assert!(text.contains("holds job 0, not job 3"), "{text}");
}

#[test]
fn real_time_experiments_cannot_be_split() {
    let (dir, _) = setup("real-time");
    for name in ["rates", "fall"] {
        let opts = Options { records: records(&dir, RecordMode::Plan), ..Options::default() };
        let err = run(name, &opts).expect_err("refused");
        assert!(format!("{err:#}").contains("real time"), "{err:#}");
    }
    let opts = Options {
        records: records(&dir, RecordMode::Run { only: Some(vec![99_999]) }),
        ..Options::default()
    };
    let err = run(goal_covering::NAME, &opts).expect_err("no job 99999");
    assert!(format!("{err:#}").contains("no job 99999"), "{err:#}");
}

/// What the fuzz target (fuzz/fuzz_targets/experiment_record.rs) checks, on the inputs nearest
/// a real record: every truncation and every single-byte change decodes or fails, never panics.
#[test]
fn records_cut_or_changed_anywhere_are_refused_without_a_panic() {
    let (dir, scenario) = setup("mutations");
    let rec = dir.join("records");
    shard(&scenario, &rec, &[1]);
    let good = std::fs::read(record_path(&rec, 1)).expect("record");
    assert_eq!(decode_for(goal_covering::NAME, &good).expect("decodes"), 1);
    for len in 0..good.len() {
        for name in RECORDABLE {
            let _ = decode_for(name, &good[..len]);
        }
    }
    for at in 0..good.len() {
        for flip in [0x01u8, 0x80, 0xff] {
            let mut bytes = good.clone();
            bytes[at] ^= flip;
            let _ = decode_for(goal_covering::NAME, &bytes);
        }
    }
}

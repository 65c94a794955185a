//! Job records: an experiment's runs split across processes or machines (`strata.sweep` on
//! Ray), then merged into the report and summary one process would have written.
//!
//! A records directory holds `manifest.json` (which sweep the records belong to) and one
//! `job-NNNNN.msgpack` per finished job. MessagePack rather than JSON because a job's result
//! holds NaN (no estimate yet) and must come back bit for bit: the merged summary has to equal
//! the single-process one.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// What to do with the records directory (`Options::records`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RecordMode {
    /// Count the jobs and write (or check) the manifest; run nothing.
    Plan,
    /// Run the jobs listed (all when `None`) whose record is missing, writing their records;
    /// no report.
    Run { only: Option<Vec<usize>> },
    /// Run nothing: load every job's record and write the report and summary.
    Merge,
}

/// `Options::records`: a records directory and what to do with it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Records {
    pub dir: PathBuf,
    pub mode: RecordMode,
}

/// What identifies a sweep: records of another one must not be mixed in.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub experiment: String,
    /// FNV-1a (64 bits, hex) of the scenario's text.
    pub scenario_hash: String,
    pub seed: u64,
    pub jobs: usize,
    /// The record format's version.
    pub format: u32,
}

const FORMAT: u32 = 1;
pub const MANIFEST: &str = "manifest.json";

impl Manifest {
    pub fn new(experiment: &str, scenario_text: &str, seed: u64, jobs: usize) -> Manifest {
        Manifest {
            experiment: experiment.to_owned(),
            scenario_hash: format!("{:016x}", fnv1a(scenario_text.as_bytes())),
            seed,
            jobs,
            format: FORMAT,
        }
    }

    /// Writes the manifest into `dir`, or checks the one there is this sweep's.
    pub fn write_or_check(&self, dir: &Path) -> Result<()> {
        let path = dir.join(MANIFEST);
        if path.exists() {
            return self.check(dir);
        }
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the records directory {}", dir.display()))?;
        write_atomic(&path, serde_json::to_string_pretty(self)?.as_bytes())
    }

    /// Checks that `dir`'s manifest is this sweep's.
    pub fn check(&self, dir: &Path) -> Result<()> {
        let path = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading the records manifest {}", path.display()))?;
        let found: Manifest = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a records manifest", path.display()))?;
        let differs = |what: &str, mine: String, theirs: String| {
            anyhow::anyhow!(
                "{} belongs to another sweep: {what} {theirs} there, {mine} here (use another \
                 records directory, or empty this one)",
                path.display()
            )
        };
        if found.format != self.format {
            return Err(differs(
                "record format",
                self.format.to_string(),
                found.format.to_string(),
            ));
        }
        if found.experiment != self.experiment {
            return Err(differs("experiment", self.experiment.clone(), found.experiment));
        }
        if found.scenario_hash != self.scenario_hash {
            return Err(differs("scenario hash", self.scenario_hash.clone(), found.scenario_hash));
        }
        if found.seed != self.seed {
            return Err(differs("seed", self.seed.to_string(), found.seed.to_string()));
        }
        if found.jobs != self.jobs {
            return Err(differs("job count", self.jobs.to_string(), found.jobs.to_string()));
        }
        Ok(())
    }
}

/// Job `index`'s record file in `dir`.
pub fn record_path(dir: &Path, index: usize) -> PathBuf {
    dir.join(format!("job-{index:05}.msgpack"))
}

/// One record on disk: the job's index (a file renamed by hand is caught) and its result.
#[derive(Serialize, Deserialize)]
struct RecordFile<R> {
    job: usize,
    result: R,
}

pub fn encode<R: Serialize>(index: usize, result: &R) -> Result<Vec<u8>> {
    rmp_serde::to_vec_named(&RecordFile { job: index, result })
        .with_context(|| format!("encoding the record of job {index}"))
}

/// Decodes a record's bytes: errors say what is wrong, never panic (the bytes come from disk).
pub fn decode<R: DeserializeOwned>(bytes: &[u8]) -> Result<(usize, R)> {
    let file: RecordFile<R> = rmp_serde::from_slice(bytes)
        .context("truncated, corrupt or not a record of this experiment")?;
    Ok((file.job, file.result))
}

/// Decodes `bytes` as a record of experiment `name` (what a merge reads from disk; the fuzz
/// target's entry): the job index it holds.
pub fn decode_for(name: &str, bytes: &[u8]) -> Result<usize> {
    match name {
        crate::goal_covering::NAME => {
            decode::<crate::goal_covering::RunResult>(bytes).map(|(job, _)| job)
        }
        crate::team::NAME => decode::<crate::team::RunResult>(bytes).map(|(job, _)| job),
        other => bail!("`{other}` has no job records"),
    }
}

/// Writes job `index`'s record to `dir` so that it appears complete or not at all.
pub fn write<R: Serialize>(dir: &Path, index: usize, result: &R) -> Result<PathBuf> {
    let path = record_path(dir, index);
    write_atomic(&path, &encode(index, result)?)?;
    Ok(path)
}

/// Reads job `index`'s record from `dir`; a missing or broken one is an error naming the file.
pub fn read<R: DeserializeOwned>(dir: &Path, index: usize, jobs: usize) -> Result<R> {
    let path = record_path(dir, index);
    let bytes = match std::fs::read(&path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "missing record {} (job {index} of {jobs}): run the sweep again to complete it",
            path.display()
        ),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let (job, result) = decode(&bytes).with_context(|| format!("record {}", path.display()))?;
    if job != index {
        bail!("record {}: holds job {job}, not job {index}", path.display());
    }
    Ok(result)
}

/// Writes through a temporary file in the same directory and renames it: a process killed
/// mid-write leaves no half record that a resumed sweep would take for a finished job.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // Unique per process and moment: two workers finishing the same job (a retried task) on a
    // shared directory must not write into one temporary file.
    let tmp = path.with_file_name(format!(".{name}.tmp-{}-{nanos}", std::process::id()));
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming to {}", path.display()))
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |hash, b| {
        (hash ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Why a record-mode run stopped before its report (not a failure): `crate::run` turns it into
/// the outcome.
#[derive(Debug)]
pub(crate) enum Stop {
    Planned { jobs: usize },
    Ran { jobs: usize, written: Vec<usize>, skipped: Vec<usize> },
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stop::Planned { jobs } => write!(f, "planned {jobs} jobs"),
            Stop::Ran { written, skipped, .. } => {
                write!(f, "wrote {} records, {} already there", written.len(), skipped.len())
            }
        }
    }
}

impl std::error::Error for Stop {}

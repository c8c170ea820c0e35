//! An online SAC run on disk, growing one checkpoint interval at a time:
//!
//! ```text
//! run.json                                      what the run is (config, task or system file)
//! transitions/steps-00000000-00010000.safetensors every step of one interval, as D4RL records it
//!                                               (`.safetensors.zst` in a snapshot: zstd, the same bytes)
//! policies/step-00010000.{safetensors,json}     the actor at each checkpoint, with its evaluation
//! checkpoints/LATEST, checkpoints/step-00010000/ networks, Adam, generator, counters, history
//! ```
//!
//! Every file is written atomically, the interval's transitions and policy
//! before the checkpoint that lists them, so `LATEST` always names a
//! checkpoint whose files are complete. The replay buffer is not saved twice:
//! a resumed run rebuilds it from the recorded intervals (checked against
//! their hashes), and the run's transitions up to any checkpoint are D4RL's
//! medium-replay.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::json_file::{read_versioned_json, write_json};
use super::policy::{PolicyMetadata, PolicyProvenance, save_policy};
use super::sac_state::{
    RngState, SacFiles, latest_checkpoint, read_sac, save_checkpoint_dir, write_sac, write_synced,
};
use super::safetensors_file::{parse_safetensors, safetensors_bytes, write_bytes};
use super::tensors::NamedTensors;
use super::{ArtifactError, sha256_hex};
use crate::agent::{OnlineRecord, OnlineSac, OnlineSacConfig};
use crate::data::{Dataset, DatasetMetadata, Recording};
use crate::envs::{System, TaskConfig};

pub const ONLINE_RUN_SCHEMA_VERSION: u32 = 1;
const RUN: &str = "run.json";
const TRANSITIONS: &str = "transitions";
const POLICIES: &str = "policies";
const CHECKPOINTS: &str = "checkpoints";
const STATE: &str = "state.json";
/// A snapshot's replay intervals are zstd-compressed: each repeats its next
/// observations and holds qpos/qvel beside them, so level 19 (the highest
/// before zstd's slow "ultra" levels) keeps about 40 % of the bytes.
const REPLAY_SUFFIX: &str = ".zst";
const REPLAY_ZSTD_LEVEL: i32 = 19;

/// `run.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OnlineRunInfo {
    pub schema_version: u32,
    pub config: OnlineSacConfig,
    /// The built-in task it trains in; none for a system file's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<TaskConfig>,
    /// The system file's text (its MJCF inlined), for a run in a file's
    /// `[mujoco]` table: a resumed run checks it, and its policies evaluate
    /// with it where the file is not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system: Option<String>,
}

impl OnlineRunInfo {
    /// The system the run in `dir` trains in.
    pub fn system(&self, dir: &Path) -> Result<System, ArtifactError> {
        let path = dir.join(RUN);
        System::recorded(self.task.clone(), self.system.as_deref(), &path)
            .map_err(|e| ArtifactError::Invalid(e.to_string()))?
            .ok_or_else(|| {
                ArtifactError::Invalid(format!(
                    "{}: names neither a task nor a system",
                    path.display()
                ))
            })
    }
}

/// One recorded interval: steps `from..to` in `file`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Interval {
    file: String,
    from: usize,
    to: usize,
    sha256: String,
}

/// A checkpoint's `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct OnlineState {
    schema_version: u32,
    step: usize,
    updates: usize,
    episodes: usize,
    rng: RngState,
    history: Vec<OnlineRecord>,
    intervals: Vec<Interval>,
    /// Set when the run was continued with an emptied replay buffer: updates
    /// resume after this step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    updates_after: Option<usize>,
    #[serde(flatten)]
    sac: SacFiles,
}

/// A policy saved at a checkpoint, with its evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct RunPolicy {
    pub step: usize,
    /// The directory and file stem to load it with [`super::load_policy`].
    pub dir: PathBuf,
    pub stem: String,
    pub metadata: PolicyMetadata,
}

/// Reads `run.json` in `dir`.
pub fn read_online_run(dir: &Path) -> Result<OnlineRunInfo, ArtifactError> {
    read_versioned_json(&dir.join(RUN), ONLINE_RUN_SCHEMA_VERSION)
}

/// Starts a run of `run` in `system` (a built-in task, or a system file
/// whose `[mujoco]` table `run` simulates) in `dir`, or checks that the run
/// already there is this one (the same knobs and system; a resumed run may
/// take more steps).
pub fn start_online_run(dir: &Path, run: &OnlineSac, system: &System) -> Result<(), ArtifactError> {
    let path = dir.join(RUN);
    if path.exists() {
        let saved = read_online_run(dir)?;
        let comparable = OnlineSacConfig {
            steps: run.config.steps,
            ..saved.config.clone()
        };
        if comparable != run.config || saved.system(dir)? != *system {
            return Err(ArtifactError::Invalid(format!(
                "{}: the run there was started with other settings; resume it with the same flags or choose another directory",
                path.display()
            )));
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| ArtifactError::io(dir, e))?;
    write_json(
        &path,
        &OnlineRunInfo {
            schema_version: ONLINE_RUN_SCHEMA_VERSION,
            config: run.config.clone(),
            task: system.task(),
            system: system.file_text(),
        },
    )
}

/// Saves the interval `run` (in `system`, as started) just finished: its
/// transitions, its policy, then the checkpoint naming them.
pub fn save_online_checkpoint(
    dir: &Path,
    run: &OnlineSac,
    system: &System,
) -> Result<PathBuf, ArtifactError> {
    let mut intervals = match latest_checkpoint(&dir.join(CHECKPOINTS))? {
        Some(checkpoint) => read_state(&checkpoint)?.intervals,
        None => Vec::new(),
    };
    let from = intervals.last().map_or(0, |i| i.to);
    let to = run.step;
    if to != from + run.recording.len() {
        return Err(ArtifactError::Invalid(format!(
            "the run is at step {to} but its last checkpoint ends at step {from} and {} steps are recorded since",
            run.recording.len()
        )));
    }
    std::fs::create_dir_all(dir.join(TRANSITIONS)).map_err(|e| ArtifactError::io(dir, e))?;
    let file = format!("{TRANSITIONS}/steps-{from:08}-{to:08}.safetensors");
    let bytes = safetensors_bytes(&recording_tensors(&run.recording), None)?;
    write_bytes(&dir.join(&file), &bytes)?;
    intervals.push(Interval {
        file,
        from,
        to,
        sha256: sha256_hex(&bytes),
    });

    let record = run.history.last();
    std::fs::create_dir_all(dir.join(POLICIES)).map_err(|e| ArtifactError::io(dir, e))?;
    save_policy(
        &dir.join(POLICIES),
        &policy_stem(to),
        &run.sac.actor,
        system,
        PolicyProvenance {
            step: to,
            normalized_score: record.map(|r| r.eval.normalized_score),
            mean_return: record.map(|r| r.eval.mean_return),
            online_training: Some(run.config.clone()),
            ..PolicyProvenance::default()
        },
    )?;

    let name = format!("step-{to:08}");
    save_checkpoint_dir(&dir.join(CHECKPOINTS), &name, |tmp| {
        let state = OnlineState {
            schema_version: ONLINE_RUN_SCHEMA_VERSION,
            step: run.step,
            updates: run.updates,
            episodes: run.episodes,
            rng: RngState::of(&run.rng),
            history: run.history.clone(),
            intervals,
            updates_after: (run.updates_after != run.config.start_steps)
                .then_some(run.updates_after),
            sac: write_sac(tmp, &run.sac)?,
        };
        write_json(&tmp.join(STATE), &state)
    })
}

/// Restores the latest checkpoint in `dir` into `run`, a fresh run built with
/// the same settings; `false` when there is none yet.
///
/// The replay buffer is rebuilt from the recorded intervals. Where they are
/// missing (a [`snapshot_online_run`] carries none), `refill` says how to go
/// on: `None` refuses, naming the first missing file; `Some(n)` continues with
/// the intervals that are there, and the policy acts `n` steps before updates
/// resume, so the buffer holds its own data before SAC samples from it.
pub fn load_online_checkpoint(
    dir: &Path,
    run: &mut OnlineSac,
    refill: Option<usize>,
) -> Result<bool, ArtifactError> {
    let Some(checkpoint) = latest_checkpoint(&dir.join(CHECKPOINTS))? else {
        return Ok(false);
    };
    let state = read_state(&checkpoint)?;
    read_sac(&checkpoint, &state.sac, &mut run.sac)?;
    let (present, missing): (Vec<&Interval>, Vec<&Interval>) = state
        .intervals
        .iter()
        .partition(|i| stored_interval(dir, i).is_some());
    if let (Some(first), None) = (missing.first(), refill) {
        return Err(ArtifactError::Invalid(format!(
            "{}: the run's transitions for steps {}..{} are not there ({} of {} intervals missing, \
             as in a snapshot); continue with --refill STEPS to rebuild the replay buffer from new steps",
            dir.join(&first.file).display(),
            first.from,
            first.to,
            missing.len(),
            state.intervals.len()
        )));
    }
    for interval in present {
        let recording = read_interval(dir, interval, &run.recording)?;
        let (o, a) = (recording.obs_dim, recording.act_dim);
        for i in 0..recording.len() {
            run.buffer.push_row(
                &recording.observations[i * o..(i + 1) * o],
                &recording.actions[i * a..(i + 1) * a],
                recording.rewards[i],
                &recording.next_observations[i * o..(i + 1) * o],
                if recording.terminals[i] { 1.0 } else { 0.0 },
            );
        }
    }
    run.rng = state.rng.restore();
    run.step = state.step;
    run.updates = state.updates;
    run.episodes = state.episodes;
    run.history = state.history;
    run.updates_after = match (missing.is_empty(), refill) {
        (false, Some(n)) => state.step + n,
        _ => state.updates_after.unwrap_or(run.config.start_steps),
    };
    Ok(true)
}

/// What [`snapshot_online_run`] kept.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSnapshot {
    /// The checkpoint's step.
    pub step: usize,
    /// The steps whose policies were kept.
    pub policies: Vec<usize>,
    /// The step up to which the transitions were kept (none: no transitions).
    pub replay_until: Option<usize>,
}

/// Copies what the run in `dir` needs to go on and to have its behaviour
/// levels picked into `out`, small enough to commit: `run.json`, the latest
/// checkpoint (networks, Adam, generator, history), and of its policies the
/// first to reach each band of `band` normalised points, the best and the
/// latest. A level's target is a fraction of the best return within a
/// tolerance (`LEVEL_TOLERANCE`), so bands narrower than it lose no pick. The
/// transitions stay behind: a run continued from a snapshot refills its replay
/// buffer ([`load_online_checkpoint`]), except, with `replay_until`, the
/// intervals up to that checkpoint step, zstd-compressed: the replay D4RL's
/// medium-replay is ([`read_run_transitions`] reads it from the snapshot as
/// from the run), which another kind of CPU cannot re-create bit for bit.
/// `out` is replaced whole.
pub fn snapshot_online_run(
    dir: &Path,
    out: &Path,
    band: f64,
    replay_until: Option<usize>,
) -> Result<RunSnapshot, ArtifactError> {
    if !(band > 0.0 && band.is_finite()) {
        return Err(ArtifactError::Invalid(format!(
            "a snapshot's score band must be positive, got {band}"
        )));
    }
    let checkpoint = latest_checkpoint(&dir.join(CHECKPOINTS))?.ok_or_else(|| {
        ArtifactError::Invalid(format!("{}: the run has no checkpoint yet", dir.display()))
    })?;
    let state = read_state(&checkpoint)?;
    let replay = match replay_until {
        Some(to) => intervals_until(dir, &state.intervals, to)?,
        None => &[],
    };
    let policies = run_policies(dir)?;
    let kept = banded_policies(&policies, band);
    let name = checkpoint
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    replace_dir(out, |tmp| {
        copy_file(&dir.join(RUN), &tmp.join(RUN))?;
        save_checkpoint_dir(&tmp.join(CHECKPOINTS), &name, |to| {
            copy_dir_files(&checkpoint, to)
        })?;
        std::fs::create_dir_all(tmp.join(POLICIES)).map_err(|e| ArtifactError::io(tmp, e))?;
        for policy in &kept {
            for ext in ["safetensors", "json"] {
                let file = format!("{}.{ext}", policy.stem);
                copy_file(&policy.dir.join(&file), &tmp.join(POLICIES).join(&file))?;
            }
        }
        if !replay.is_empty() {
            std::fs::create_dir_all(tmp.join(TRANSITIONS))
                .map_err(|e| ArtifactError::io(tmp, e))?;
        }
        for interval in replay {
            compress_interval(dir, interval, tmp)?;
        }
        Ok(())
    })?;
    Ok(RunSnapshot {
        step: state.step,
        policies: kept.iter().map(|p| p.step).collect(),
        replay_until,
    })
}

/// The run's intervals from its start to checkpoint step `to`, each file present.
fn intervals_until<'a>(
    dir: &Path,
    intervals: &'a [Interval],
    to: usize,
) -> Result<&'a [Interval], ArtifactError> {
    let Some(last) = intervals.iter().position(|i| i.to == to) else {
        let ends: Vec<usize> = intervals.iter().map(|i| i.to).collect();
        return Err(ArtifactError::Invalid(format!(
            "{}: step {to} is not a checkpoint of the run (its checkpoints end at steps {ends:?})",
            dir.display()
        )));
    };
    let kept = &intervals[..=last];
    if let Some(missing) = kept.iter().find(|i| stored_interval(dir, i).is_none()) {
        return Err(ArtifactError::Invalid(format!(
            "{}: the run's transitions for steps {}..{} are not there, so its replay up to step {to} cannot be kept",
            dir.join(&missing.file).display(),
            missing.from,
            missing.to
        )));
    }
    Ok(kept)
}

/// The first policy in each `band`-point band of normalised score, the best
/// and the latest, by step.
fn banded_policies(policies: &[RunPolicy], band: f64) -> Vec<&RunPolicy> {
    let score = |p: &RunPolicy| p.metadata.provenance.normalized_score.unwrap_or(f64::NAN);
    let best = policies
        .iter()
        .filter(|p| score(p).is_finite())
        .max_by(|a, b| score(a).total_cmp(&score(b)))
        .map(|p| p.step);
    let latest = policies.last().map(|p| p.step);
    let mut bands = std::collections::BTreeSet::new();
    policies
        .iter()
        .filter(|p| {
            let first_in_band =
                score(p).is_finite() && bands.insert((score(p) / band).floor() as i64);
            first_in_band || Some(p.step) == best || Some(p.step) == latest
        })
        .collect()
}

/// Writes directory `out` whole with `write` (into a temporary sibling, then
/// swapped in), so a failure leaves the old one.
fn replace_dir(
    out: &Path,
    write: impl FnOnce(&Path) -> Result<(), ArtifactError>,
) -> Result<(), ArtifactError> {
    let sibling = |tag: &str| {
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        out.with_file_name(format!(".{name}.{tag}-{}", std::process::id()))
    };
    let (tmp, old) = (sibling("tmp"), sibling("old"));
    for stale in [&tmp, &old] {
        if stale.exists() {
            std::fs::remove_dir_all(stale).map_err(|e| ArtifactError::io(stale, e))?;
        }
    }
    std::fs::create_dir_all(&tmp).map_err(|e| ArtifactError::io(&tmp, e))?;
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    if out.exists() {
        std::fs::rename(out, &old).map_err(|e| ArtifactError::io(out, e))?;
    }
    std::fs::rename(&tmp, out).map_err(|e| ArtifactError::io(out, e))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| ArtifactError::io(&old, e))?;
    }
    Ok(())
}

/// Where an interval's transitions are: the run's own file, or a snapshot's
/// compressed copy of it.
fn stored_interval(dir: &Path, interval: &Interval) -> Option<PathBuf> {
    let plain = dir.join(&interval.file);
    let compressed = dir.join(format!("{}{REPLAY_SUFFIX}", interval.file));
    [plain, compressed].into_iter().find(|p| p.is_file())
}

/// An interval's safetensors bytes from `path` ([`stored_interval`]),
/// decompressed where compressed, and checked against the recorded hash.
fn interval_bytes(path: &Path, interval: &Interval) -> Result<Vec<u8>, ArtifactError> {
    let stored = std::fs::read(path).map_err(|e| ArtifactError::io(path, e))?;
    let bytes = if path.to_string_lossy().ends_with(REPLAY_SUFFIX) {
        zstd::decode_all(stored.as_slice()).map_err(|e| {
            ArtifactError::Invalid(format!("{}: not a zstd stream ({e})", path.display()))
        })?
    } else {
        stored
    };
    if sha256_hex(&bytes) != interval.sha256 {
        return Err(ArtifactError::HashMismatch {
            file: path.to_path_buf(),
        });
    }
    Ok(bytes)
}

/// Writes run `dir`'s `interval` into the snapshot being written in `out`,
/// compressed, after checking it against its hash.
fn compress_interval(dir: &Path, interval: &Interval, out: &Path) -> Result<(), ArtifactError> {
    let path = stored_interval(dir, interval)
        .ok_or_else(|| ArtifactError::Invalid(format!("{}: missing", interval.file)))?;
    let bytes = interval_bytes(&path, interval)?;
    let compressed = zstd::encode_all(bytes.as_slice(), REPLAY_ZSTD_LEVEL)
        .map_err(|e| ArtifactError::io(&path, e))?;
    write_synced(
        &out.join(format!("{}{REPLAY_SUFFIX}", interval.file)),
        &compressed,
    )
}

/// Copies a file, fsynced.
fn copy_file(from: &Path, to: &Path) -> Result<(), ArtifactError> {
    let bytes = std::fs::read(from).map_err(|e| ArtifactError::io(from, e))?;
    write_synced(to, &bytes)
}

/// Copies the plain files of directory `from` into `to`.
fn copy_dir_files(from: &Path, to: &Path) -> Result<(), ArtifactError> {
    for entry in std::fs::read_dir(from).map_err(|e| ArtifactError::io(from, e))? {
        let path = entry.map_err(|e| ArtifactError::io(from, e))?.path();
        if let Some(name) = path.file_name().filter(|_| path.is_file()) {
            copy_file(&path, &to.join(name))?;
        }
    }
    Ok(())
}

/// The run's transitions from its start to checkpoint step `to`, in D4RL's
/// layout: D4RL's medium-replay when `to` is the medium policy's step.
pub fn read_run_transitions(dir: &Path, to: usize) -> Result<Dataset, ArtifactError> {
    let info = read_online_run(dir)?;
    let checkpoint = latest_checkpoint(&dir.join(CHECKPOINTS))?.ok_or_else(|| {
        ArtifactError::Invalid(format!("{}: the run has no checkpoint yet", dir.display()))
    })?;
    let state = read_state(&checkpoint)?;
    let intervals = intervals_until(dir, &state.intervals, to)?;
    let task = info.system(dir)?.simulator().ok_or_else(|| {
        ArtifactError::Invalid(format!(
            "{}: the run's system has no simulator",
            dir.display()
        ))
    })?;
    let probe =
        crate::envs::MujocoTask::new(&task).map_err(|e| ArtifactError::Invalid(e.to_string()))?;
    let mut all = Recording::for_task(&probe);
    for interval in intervals {
        all.append(read_interval(dir, interval, &all)?);
    }
    let mut metadata = DatasetMetadata::new();
    metadata.insert("task".into(), task.task.to_string());
    metadata.insert(
        "observation_layout".into(),
        format!("{:?}", task.layout).to_lowercase(),
    );
    all.into_dataset(metadata, dir)
        .map_err(|e| ArtifactError::Invalid(e.to_string()))
}

/// Every policy the run holds, by step, with its evaluation (a snapshot
/// holds some of them).
pub fn run_policies(dir: &Path) -> Result<Vec<RunPolicy>, ArtifactError> {
    let checkpoint = latest_checkpoint(&dir.join(CHECKPOINTS))?.ok_or_else(|| {
        ArtifactError::Invalid(format!("{}: the run has no checkpoint yet", dir.display()))
    })?;
    let state = read_state(&checkpoint)?;
    let policies = dir.join(POLICIES);
    state
        .intervals
        .iter()
        .filter(|interval| {
            policies
                .join(format!("{}.json", policy_stem(interval.to)))
                .exists()
        })
        .map(|interval| {
            let stem = policy_stem(interval.to);
            let metadata = read_versioned_json(
                &policies.join(format!("{stem}.json")),
                super::POLICY_SCHEMA_VERSION,
            )?;
            Ok(RunPolicy {
                step: interval.to,
                dir: policies.clone(),
                stem,
                metadata,
            })
        })
        .collect()
}

fn policy_stem(step: usize) -> String {
    format!("step-{step:08}")
}

fn read_state(checkpoint: &Path) -> Result<OnlineState, ArtifactError> {
    read_versioned_json(&checkpoint.join(STATE), ONLINE_RUN_SCHEMA_VERSION)
}

/// The columns of a recording as named tensors (flags as 0/1).
fn recording_tensors(r: &Recording) -> NamedTensors {
    let n = r.len();
    let flags = |v: &[bool]| v.iter().map(|&b| f32::from(u8::from(b))).collect();
    let mut tensors = NamedTensors::from([
        (
            "observations".into(),
            (vec![n, r.obs_dim], r.observations.clone()),
        ),
        ("actions".into(), (vec![n, r.act_dim], r.actions.clone())),
        ("rewards".into(), (vec![n], r.rewards.clone())),
        (
            "next_observations".into(),
            (vec![n, r.obs_dim], r.next_observations.clone()),
        ),
        ("terminals".into(), (vec![n], flags(&r.terminals))),
        ("timeouts".into(), (vec![n], flags(&r.timeouts))),
        ("qpos".into(), (vec![n, r.nq], r.qpos.clone())),
        ("qvel".into(), (vec![n, r.nv], r.qvel.clone())),
    ]);
    if r.logged {
        tensors.insert("action_log_probs".into(), (vec![n], r.log_probs.clone()));
    }
    tensors
}

/// Reads one interval, checked against its hash and `like`'s widths.
fn read_interval(
    dir: &Path,
    interval: &Interval,
    like: &Recording,
) -> Result<Recording, ArtifactError> {
    let Some(path) = stored_interval(dir, interval) else {
        return Err(ArtifactError::Invalid(format!(
            "{}: the run's transitions for steps {}..{} are not there (a snapshot carries none; \
             they are on the machine that ran those steps)",
            dir.join(&interval.file).display(),
            interval.from,
            interval.to
        )));
    };
    let mut tensors = parse_safetensors(&interval_bytes(&path, interval)?, &path)?;
    let n = interval.to - interval.from;
    // Runs record them whenever the policy has a density; present, they must fit.
    let has_log_probs = tensors.contains_key("action_log_probs");
    let mut take = |name: &str, width: Option<usize>| -> Result<Vec<f32>, ArtifactError> {
        let (dims, values) = tensors
            .remove(name)
            .ok_or_else(|| ArtifactError::MissingTensor(format!("{}: {name}", path.display())))?;
        let expected: Vec<usize> = std::iter::once(n).chain(width).collect();
        if dims != expected {
            return Err(ArtifactError::TensorShape {
                name: format!("{}: {name}", path.display()),
                expected,
                got: dims,
            });
        }
        Ok(values)
    };
    let flags = |v: Vec<f32>| v.into_iter().map(|x| x != 0.0).collect();
    let log_probs = if has_log_probs {
        Some(take("action_log_probs", None)?)
    } else {
        None
    };
    Ok(Recording {
        observations: take("observations", Some(like.obs_dim))?,
        actions: take("actions", Some(like.act_dim))?,
        rewards: take("rewards", None)?,
        next_observations: take("next_observations", Some(like.obs_dim))?,
        terminals: flags(take("terminals", None)?),
        timeouts: flags(take("timeouts", None)?),
        qpos: take("qpos", Some(like.nq))?,
        qvel: take("qvel", Some(like.nv))?,
        logged: log_probs.is_some(),
        log_probs: log_probs.unwrap_or_default(),
        obs_dim: like.obs_dim,
        act_dim: like.act_dim,
        nq: like.nq,
        nv: like.nv,
    })
}

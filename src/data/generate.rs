//! Dataset generation in D4RL's recipe: run a behaviour policy in the real
//! task and record every transition, with the full MuJoCo state of each
//! observation. Episodes run in parallel rounds; episode `e` resets with its
//! own seed and draws policy noise from its own stream, so the dataset depends
//! on the seed alone, never on the number of cores.

use ndarray::{Array1, Array2};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::dataset::DatasetParts;
use super::{DataError, Dataset, DatasetMetadata};
use crate::envs::{MujocoTask, TaskConfig};
use crate::shared::BatchPolicy;

/// What to generate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GenerateConfig {
    pub task: TaskConfig,
    /// Transitions to record; the last episode is cut (as a timeout) to fit.
    pub transitions: usize,
    pub seed: u64,
    /// The recipe's name, stored in the metadata (`random`, `medium`, ...).
    pub kind: String,
    /// Episodes run in parallel per round.
    pub episodes_per_round: usize,
}

impl GenerateConfig {
    pub fn new(task: TaskConfig, kind: &str, transitions: usize, seed: u64) -> Self {
        Self {
            task,
            transitions,
            seed,
            kind: kind.into(),
            episodes_per_round: 64,
        }
    }
}

/// The rows of one recorded episode.
#[derive(Default)]
struct Episode {
    observations: Vec<f32>,
    actions: Vec<f32>,
    rewards: Vec<f32>,
    next_observations: Vec<f32>,
    terminals: Vec<bool>,
    timeouts: Vec<bool>,
    qpos: Vec<f32>,
    qvel: Vec<f32>,
}

/// Runs `policy` in `config.task` until `config.transitions` transitions are
/// recorded. `progress` is called with the length of each finished episode.
pub fn generate(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    policy_description: &str,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Dataset, DataError> {
    let probe = MujocoTask::new(config.task)?;
    let (obs_dim, act_dim) = (probe.obs_dim(), probe.act_dim());
    let (nq, nv) = (probe.qpos().len(), probe.qvel().len());
    let mut all = Episode::default();
    let mut recorded = 0;
    let mut next_episode = 0u64;
    while recorded < config.transitions {
        let round = next_episode..next_episode + config.episodes_per_round.max(1) as u64;
        next_episode = round.end;
        let episodes: Vec<Episode> = round
            .into_par_iter()
            .map(|e| {
                let episode = run_episode(config, policy, e)?;
                progress(episode.rewards.len());
                Ok(episode)
            })
            .collect::<Result<_, DataError>>()?;
        for mut episode in episodes {
            let keep = episode.rewards.len().min(config.transitions - recorded);
            if keep == 0 {
                break;
            }
            if keep < episode.rewards.len() {
                truncate(&mut episode, keep, obs_dim, act_dim, nq, nv);
            }
            recorded += keep;
            append(&mut all, episode);
        }
    }

    let mut metadata = DatasetMetadata::new();
    metadata.insert("task".into(), config.task.name.to_string());
    metadata.insert(
        "observation_layout".into(),
        format!("{:?}", config.task.layout).to_lowercase(),
    );
    metadata.insert("kind".into(), config.kind.clone());
    metadata.insert("seed".into(), config.seed.to_string());
    metadata.insert("policy".into(), policy_description.into());
    metadata.insert(
        "generator".into(),
        format!("nuno {}", env!("CARGO_PKG_VERSION")),
    );
    let n = all.rewards.len();
    let generated = std::path::Path::new("<generated>");
    let matrix = |v: Vec<f32>, width: usize| {
        Array2::from_shape_vec((n, width), v).map_err(|e| DataError::Invalid {
            file: generated.to_path_buf(),
            message: format!("recorded rows do not form [{n}, {width}]: {e}"),
        })
    };
    let parts = DatasetParts {
        observations: matrix(all.observations, obs_dim)?,
        actions: matrix(all.actions, act_dim)?,
        rewards: Array1::from(all.rewards),
        next_observations: matrix(all.next_observations, obs_dim)?,
        terminals: all.terminals,
        timeouts: all.timeouts,
        qpos: Some(matrix(all.qpos, nq)?),
        qvel: Some(matrix(all.qvel, nv)?),
        metadata,
    };
    Dataset::from_parts(parts, generated)
}

/// One full episode of `policy`, seeded by `(config.seed, episode)`.
fn run_episode(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    episode: u64,
) -> Result<Episode, DataError> {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    rng.set_stream(episode);
    let mut task = MujocoTask::new(config.task)?;
    let reset_seed = rand::Rng::random::<u64>(&mut rng);
    let mut obs: Vec<f32> = task
        .reset(Some(reset_seed))
        .iter()
        .map(|&x| x as f32)
        .collect();
    let mut out = Episode::default();
    loop {
        let action = policy.act(&obs, &mut rng);
        let action_f64: Vec<f64> = action.iter().map(|&a| f64::from(a)).collect();
        out.qpos.extend(task.qpos().iter().map(|&x| x as f32));
        out.qvel.extend(task.qvel().iter().map(|&x| x as f32));
        let step = task.step(&action_f64)?;
        let next: Vec<f32> = step.observation.iter().map(|&x| x as f32).collect();
        out.observations.extend(&obs);
        out.actions.extend(&action);
        out.rewards.push(step.reward as f32);
        out.next_observations.extend(&next);
        out.terminals.push(step.terminated);
        out.timeouts.push(step.truncated && !step.terminated);
        if step.terminated || step.truncated {
            return Ok(out);
        }
        obs = next;
    }
}

/// Keeps the first `keep` transitions of an episode, the last one now a timeout.
fn truncate(e: &mut Episode, keep: usize, obs_dim: usize, act_dim: usize, nq: usize, nv: usize) {
    e.observations.truncate(keep * obs_dim);
    e.actions.truncate(keep * act_dim);
    e.rewards.truncate(keep);
    e.next_observations.truncate(keep * obs_dim);
    e.terminals.truncate(keep);
    e.timeouts.truncate(keep);
    e.qpos.truncate(keep * nq);
    e.qvel.truncate(keep * nv);
    if let (Some(t), Some(c)) = (e.terminals.last(), e.timeouts.last_mut()) {
        *c = !*t;
    }
}

fn append(all: &mut Episode, e: Episode) {
    all.observations.extend(e.observations);
    all.actions.extend(e.actions);
    all.rewards.extend(e.rewards);
    all.next_observations.extend(e.next_observations);
    all.terminals.extend(e.terminals);
    all.timeouts.extend(e.timeouts);
    all.qpos.extend(e.qpos);
    all.qvel.extend(e.qvel);
}

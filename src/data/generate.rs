//! Dataset generation in D4RL's recipe: run a behaviour policy in the real
//! task and record every transition, with the full MuJoCo state of each
//! observation. Episodes run in parallel rounds; episode `e` resets with its
//! own seed and draws policy noise from its own stream, so the dataset depends
//! on the seed alone, never on the number of cores.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::recording::Recording;
use super::{DataError, Dataset, DatasetMetadata};
use crate::envs::{MujocoTask, ObservationLayout, TaskConfig};
use crate::shared::BatchPolicy;

/// How much to record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Budget {
    /// This many transitions (D4RL's 1M); the last episode is cut (as a timeout) to fit.
    Transitions(usize),
    /// This many whole episodes (NeoRL's 1000 trajectories).
    Episodes(usize),
}

/// What to generate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GenerateConfig {
    pub task: TaskConfig,
    pub budget: Budget,
    pub seed: u64,
    /// The recipe's name, stored in the metadata (`random`, `medium`, ...).
    pub kind: String,
    /// Episodes run in parallel per round.
    pub episodes_per_round: usize,
    /// The observations the policy takes: the task's, or D4RL's in a NeoRL
    /// task (root x dropped), so one behaviour policy serves both benchmarks.
    pub policy_layout: ObservationLayout,
}

impl GenerateConfig {
    /// Leading observation columns the policy does not see: root x, when a
    /// D4RL-layout policy acts in a NeoRL-layout task.
    fn root_x_dropped(&self) -> usize {
        usize::from(self.task.layout != self.policy_layout)
    }

    pub fn new(task: TaskConfig, kind: &str, transitions: usize, seed: u64) -> Self {
        Self {
            policy_layout: task.layout,
            task,
            budget: Budget::Transitions(transitions),
            seed,
            kind: kind.into(),
            episodes_per_round: 64,
        }
    }
}

/// Runs `policy` in `config.task` until `config.budget` is recorded.
/// `progress` is called with the length of each finished episode.
pub fn generate(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    policy_description: &str,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Dataset, DataError> {
    let probe = MujocoTask::new(&config.task)?;
    check_policy_fits(config, policy, &probe)?;
    let recorded = record_episodes(config, policy, &probe, progress)?;
    let metadata = generated_metadata(config, policy_description);
    recorded.into_dataset(metadata, std::path::Path::new("<generated>"))
}

/// That `policy` reads the task's observations, as `config.policy_layout`
/// gives them, and acts in its action space.
fn check_policy_fits(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    probe: &MujocoTask,
) -> Result<(), DataError> {
    let root_x = config.root_x_dropped();
    let expected = (probe.obs_dim() - root_x, probe.act_dim());
    if config.task.layout == ObservationLayout::D4rl && root_x == 1 {
        return Err(DataError::Behaviour(
            "a policy on NeoRL observations cannot act in a D4RL-layout task (root x is not observed)"
                .into(),
        ));
    }
    if (policy.obs_dim(), policy.act_dim()) != expected {
        return Err(DataError::Behaviour(format!(
            "the policy takes observations of width {} and gives actions of width {}; {} ({:?} observations) needs {} and {}",
            policy.obs_dim(),
            policy.act_dim(),
            config.task.task,
            config.policy_layout,
            expected.0,
            expected.1
        )));
    }
    Ok(())
}

/// Whole episodes, `config.episodes_per_round` at a time on the cores, until
/// the budget is met; the last one kept is cut to a transition budget.
fn record_episodes(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    probe: &MujocoTask,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Recording, DataError> {
    let mut all = Recording::for_task(probe);
    let mut episodes_kept = 0;
    let done = |recorded: usize, episodes: usize| match config.budget {
        Budget::Transitions(n) => recorded >= n,
        Budget::Episodes(n) => episodes >= n,
    };
    let mut next_episode = 0u64;
    while !done(all.len(), episodes_kept) {
        let round = next_episode..next_episode + config.episodes_per_round.max(1) as u64;
        next_episode = round.end;
        let episodes: Vec<Recording> = round
            .into_par_iter()
            .map(|e| {
                let episode = run_episode(config, policy, e)?;
                progress(episode.len());
                Ok(episode)
            })
            .collect::<Result<_, DataError>>()?;
        for mut episode in episodes {
            if done(all.len(), episodes_kept) {
                break;
            }
            if let Budget::Transitions(n) = config.budget
                && episode.len() > n - all.len()
            {
                episode.truncate(n - all.len());
            }
            episodes_kept += 1;
            all.append(episode);
        }
    }
    Ok(all)
}

/// The recipe's record: task, layouts, kind, seed, policy and generator.
fn generated_metadata(config: &GenerateConfig, policy_description: &str) -> DatasetMetadata {
    let mut metadata = DatasetMetadata::new();
    metadata.insert("task".into(), config.task.task.to_string());
    metadata.insert(
        "observation_layout".into(),
        format!("{:?}", config.task.layout).to_lowercase(),
    );
    metadata.insert("kind".into(), config.kind.clone());
    metadata.insert("seed".into(), config.seed.to_string());
    metadata.insert("policy".into(), policy_description.into());
    metadata.insert(
        "policy_observation_layout".into(),
        format!("{:?}", config.policy_layout).to_lowercase(),
    );
    metadata.insert("generator".into(), generator());
    metadata
}

/// The `generator` every dataset nuno writes records: this library's version.
pub fn generator() -> String {
    format!("nuno {}", env!("CARGO_PKG_VERSION"))
}

/// One full episode of `policy`, seeded by `(config.seed, episode)`.
fn run_episode(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    episode: u64,
) -> Result<Recording, DataError> {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    rng.set_stream(episode);
    let mut task = MujocoTask::new(&config.task)?;
    let reset_seed = rand::Rng::random::<u64>(&mut rng);
    let mut obs: Vec<f32> = task
        .reset(Some(reset_seed))
        .iter()
        .map(|&x| x as f32)
        .collect();
    let mut out = Recording::for_task(&task);
    loop {
        let logged = policy.act_logged(&obs[config.root_x_dropped()..], &mut rng);
        let action: Vec<f64> = logged.actions.iter().map(|&a| f64::from(a)).collect();
        let state = (task.qpos().to_vec(), task.qvel().to_vec());
        let step = task.step(&action)?;
        let log_prob = logged.log_probs.map(|l| l[0]);
        out.push(&obs, (&state.0, &state.1), &logged.actions, log_prob, &step);
        if step.terminated || step.truncated {
            return Ok(out);
        }
        obs = step.observation.iter().map(|&x| x as f32).collect();
    }
}

//! Runs a policy for N episodes in the real MuJoCo task, spread over threads.
//!
//! Episodes are cut into fixed groups that step in lockstep, so the policy sees
//! a batch of states per call; groups run in parallel on rayon's pool. Episode
//! `i` resets with seed `seed + i` (mod 2⁶⁴) and group `g` draws policy noise from its own
//! generator seeded by `(seed, g)`, so a report depends on the seed alone, not
//! on the number of threads.
//!
//! What acts is a [`BatchPolicy`] or, for a controller that keeps something
//! per episode (model-predictive control's last plan), an [`EpisodeController`].

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{EnvError, MujocoTask, TaskConfig};
use crate::shared::cancel::Cancel;
use crate::shared::{BatchPolicy, SeedStream, derive_seed, mean_std_population};

/// What to evaluate and how.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationConfig {
    pub task: TaskConfig,
    pub episodes: usize,
    pub seed: u64,
    /// Episodes stepped together, i.e. the policy's batch size.
    pub episodes_per_group: usize,
}

impl EvaluationConfig {
    /// `episodes` episodes of `task` from `seed`, 8 episodes a batch.
    pub fn new(task: TaskConfig, episodes: usize, seed: u64) -> Self {
        Self {
            task,
            episodes,
            seed,
            episodes_per_group: 8,
        }
    }
}

/// Per-episode results and their summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct EvaluationReport {
    pub returns: Vec<f64>,
    pub lengths: Vec<usize>,
    pub normalized_scores: Vec<f64>,
    pub mean_return: f64,
    pub std_return: f64,
    pub mean_normalized_score: f64,
    pub std_normalized_score: f64,
}

/// What acts in evaluated episodes when a batch policy is not enough: it is
/// told which episode each row is, so it can keep state per episode. One is
/// made per group of episodes, so it never needs to be shared across threads.
pub trait EpisodeController {
    fn obs_dim(&self) -> usize;
    fn act_dim(&self) -> usize;
    /// Actions `[rows, act_dim]` for `observations` (`[rows, obs_dim]`); row
    /// i is episode `episodes[i]`'s. A long step checks `cancel`.
    fn act(
        &mut self,
        episodes: &[usize],
        observations: &[f32],
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<Vec<f32>, EnvError>;
}

/// A batch policy as a controller: it keeps nothing per episode.
struct PolicyController<'a>(&'a dyn BatchPolicy);

impl EpisodeController for PolicyController<'_> {
    fn obs_dim(&self) -> usize {
        self.0.obs_dim()
    }

    fn act_dim(&self) -> usize {
        self.0.act_dim()
    }

    fn act(
        &mut self,
        _: &[usize],
        observations: &[f32],
        rng: &mut ChaCha8Rng,
        _: &Cancel,
    ) -> Result<Vec<f32>, EnvError> {
        Ok(self.0.act(observations, rng))
    }
}

/// Runs `policy` for `config.episodes` episodes of `config.task`.
pub fn evaluate(
    policy: &dyn BatchPolicy,
    config: &EvaluationConfig,
) -> Result<EvaluationReport, EnvError> {
    evaluate_or_cancel(policy, config, &Cancel::default())
}

/// [`evaluate`], stopping with [`EnvError::Cancelled`] at the next step of
/// every episode once `cancel` is set.
pub fn evaluate_or_cancel(
    policy: &dyn BatchPolicy,
    config: &EvaluationConfig,
    cancel: &Cancel,
) -> Result<EvaluationReport, EnvError> {
    evaluate_controlled(&|| PolicyController(policy), config, cancel)
}

/// [`evaluate_or_cancel`] for a controller that keeps state per episode:
/// `controller()` makes a fresh one for each group of episodes.
pub fn evaluate_controlled<C: EpisodeController>(
    controller: &(dyn Fn() -> C + Sync),
    config: &EvaluationConfig,
    cancel: &Cancel,
) -> Result<EvaluationReport, EnvError> {
    if config.episodes == 0 {
        return Err(EnvError::NoEpisodes);
    }
    let probe = MujocoTask::new(&config.task)?;
    let widths = controller();
    for (what, policy_dim, task_dim) in [
        ("observations of width", widths.obs_dim(), probe.obs_dim()),
        ("actions of width", widths.act_dim(), probe.act_dim()),
    ] {
        if policy_dim != task_dim {
            return Err(EnvError::PolicyMismatch {
                what,
                policy: policy_dim,
                task: task_dim,
            });
        }
    }

    let group = config.episodes_per_group.max(1);
    let starts: Vec<usize> = (0..config.episodes).step_by(group).collect();
    let groups: Vec<Vec<(f64, usize)>> = starts
        .par_iter()
        .enumerate()
        .map(|(g, &first)| {
            let episodes = first..(first + group).min(config.episodes);
            run_group(&mut controller(), config, g as u64, episodes, cancel)
        })
        .collect::<Result<_, _>>()?;
    let (returns, lengths): (Vec<f64>, Vec<usize>) = groups.into_iter().flatten().unzip();

    let reference = config.task.score_reference();
    let normalized_scores: Vec<f64> = returns.iter().map(|&r| reference.normalize(r)).collect();
    let (mean_return, std_return) = mean_std_population(&returns);
    let (mean_normalized_score, std_normalized_score) = mean_std_population(&normalized_scores);
    Ok(EvaluationReport {
        returns,
        lengths,
        normalized_scores,
        mean_return,
        std_return,
        mean_normalized_score,
        std_normalized_score,
    })
}

/// Steps the episodes of one group in lockstep until each has ended; returns
/// (return, length) per episode.
fn run_group(
    controller: &mut impl EpisodeController,
    config: &EvaluationConfig,
    group_index: u64,
    episodes: std::ops::Range<usize>,
    cancel: &Cancel,
) -> Result<Vec<(f64, usize)>, EnvError> {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    rng.set_stream(group_index + 1);
    let first = episodes.start;
    let mut tasks = Vec::with_capacity(episodes.len());
    let mut observations = Vec::with_capacity(episodes.len());
    for episode in episodes {
        let mut task = MujocoTask::new(&config.task)?;
        observations.push(task.reset(Some(derive_seed(
            config.seed,
            SeedStream::Episode(episode as u64),
        ))));
        tasks.push(task);
    }
    let obs_dim = controller.obs_dim();
    let act_dim = controller.act_dim();
    let mut results = vec![(0.0, 0); tasks.len()];
    let mut running: Vec<usize> = (0..tasks.len()).collect();
    let mut batch = Vec::with_capacity(tasks.len() * obs_dim);
    while !running.is_empty() {
        cancel.check()?;
        batch.clear();
        for &i in &running {
            batch.extend(observations[i].iter().map(|&x| x as f32));
        }
        let numbers: Vec<usize> = running.iter().map(|&i| first + i).collect();
        let actions = controller.act(&numbers, &batch, &mut rng, cancel)?;
        if actions.len() != running.len() * act_dim {
            return Err(EnvError::PolicyOutput {
                batch: running.len(),
                expected: running.len() * act_dim,
                got: actions.len(),
            });
        }
        let mut still_running = Vec::with_capacity(running.len());
        for (row, &i) in running.iter().enumerate() {
            let action: Vec<f64> = actions[row * act_dim..(row + 1) * act_dim]
                .iter()
                .map(|&a| f64::from(a))
                .collect();
            let step = tasks[i].step(&action)?;
            results[i].0 += step.reward;
            results[i].1 += 1;
            observations[i] = step.observation;
            if !(step.terminated || step.truncated) {
                still_running.push(i);
            }
        }
        running = still_running;
    }
    Ok(results)
}

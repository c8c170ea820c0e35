//! Sampling planners over [`score_sequences`]: the cross-entropy method,
//! iCEM and MPPI as mbrl-lib runs them (`mbrl/planning/trajectory_opt.py`; the facts
//! are in `../shared/reference/nuno-code-and-planners.md`, Part B), with the
//! objective a candidate's η-penalised return (or its CVaR over particles),
//! and a warm start from the previous control step's plan.
//!
//! Where this departs from mbrl-lib, and why (docs/paper-map.md):
//! - a candidate whose objective is NaN (a diverged model) ranks last, where
//!   mbrl-lib gives it −1e-10, above every negative return;
//! - MPPI's noise is scaled by its `noise` (mbrl-lib overwrites its σ-scaled
//!   population, so σ has no effect there) and its weights are
//!   exp((R − max R)/temperature) (mbrl-lib's γ is 1/temperature).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::PlanningError;
use super::colored_noise::ColoredNoise;
use super::score::{CandidateScore, Candidates, ScoreConfig, score_sequences};
use crate::envs::Rules;
use crate::shared::{BatchDynamics, Cancel};

/// The planners, by name: the server's `planner`, the trainer's `--planner`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Planner {
    Mppi,
    Cem,
    Icem,
}

crate::shared::named_enum!(Planner, "planner", Planner::Mppi => "mppi", Planner::Cem => "cem", Planner::Icem => "icem");

/// A planner's own settings as a caller gives them, each optional; what is
/// left out takes mbrl-lib's default (PETS' for CEM).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PlannerSettings {
    /// MPPI's temperature (default 1).
    pub temperature: Option<f64>,
    /// MPPI's β (default 0.9).
    pub smoothing: Option<f64>,
    /// CEM's and iCEM's elites (default ⌈population / 10⌉, at most the population).
    pub elites: Option<usize>,
    /// CEM's and iCEM's momentum α (default 0.1).
    pub momentum: Option<f64>,
    /// iCEM's population decay: iteration i samples population·decay^(−i) (default 1.3).
    pub decay: Option<f64>,
    /// iCEM's noise exponent β: power ∝ f^(−β) along time (default 2; 0 is white).
    pub colored_noise: Option<f64>,
    /// iCEM's share of elites carried to the next iteration and call (default 0.3).
    pub keep_elites: Option<f64>,
    /// The sampling spread (default: CEM and iCEM 0.5, MPPI 1; see [`PlanConfig::noise`]).
    pub noise: Option<f64>,
}

impl Planner {
    /// This planner with `settings` over its defaults, and its noise; a
    /// setting of the other planner is refused, not ignored.
    pub fn configure(
        self,
        settings: &PlannerSettings,
        population: usize,
    ) -> Result<(Optimizer, f64), PlanningError> {
        let misplaced = |fields: &str, owner: Planner| {
            Err(PlanningError::Invalid(format!(
                "{fields} are settings of {owner}, not of {self}"
            )))
        };
        let icem_only = settings.decay.is_some()
            || settings.colored_noise.is_some()
            || settings.keep_elites.is_some();
        let mppi_only = settings.temperature.is_some() || settings.smoothing.is_some();
        let elites = (settings.elites)
            .unwrap_or(population.div_ceil(10))
            .min(population);
        let momentum = settings.momentum.unwrap_or(0.1);
        let optimizer = match self {
            Planner::Mppi => {
                if settings.elites.is_some() || settings.momentum.is_some() {
                    return misplaced("`elites` and `momentum`", Planner::Cem);
                }
                if icem_only {
                    return misplaced("`decay`, `colored_noise` and `keep_elites`", Planner::Icem);
                }
                Optimizer::Mppi(MppiConfig {
                    temperature: settings.temperature.unwrap_or(1.0),
                    smoothing: settings.smoothing.unwrap_or(0.9),
                })
            }
            Planner::Cem => {
                if mppi_only {
                    return misplaced("`temperature` and `smoothing`", Planner::Mppi);
                }
                if icem_only {
                    return misplaced("`decay`, `colored_noise` and `keep_elites`", Planner::Icem);
                }
                Optimizer::Cem(CemConfig { elites, momentum })
            }
            Planner::Icem => {
                if mppi_only {
                    return misplaced("`temperature` and `smoothing`", Planner::Mppi);
                }
                Optimizer::Icem(IcemConfig {
                    elites,
                    momentum,
                    decay: settings.decay.unwrap_or(1.3),
                    colored_noise: settings.colored_noise.unwrap_or(2.0),
                    keep_elites: settings.keep_elites.unwrap_or(0.3),
                })
            }
        };
        let noise = settings.noise.unwrap_or(match self {
            Planner::Cem | Planner::Icem => 0.5,
            Planner::Mppi => 1.0,
        });
        Ok((optimizer, noise))
    }
}

/// Which planner, with its own settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Optimizer {
    Cem(CemConfig),
    Icem(IcemConfig),
    Mppi(MppiConfig),
}

/// The cross-entropy method (mbrl-lib's `CEMOptimizer`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CemConfig {
    /// The best candidates each iteration refits the sampling distribution to.
    pub elites: usize,
    /// α: the share of the old mean and variance kept at each refit (PETS: 0.1).
    pub momentum: f64,
}

/// The improved cross-entropy method (Pinneri et al. 2020; mbrl-lib's
/// `ICEMOptimizer`): coloured noise along time, a population that shrinks
/// each iteration, and elites carried to the next iteration and the next
/// control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcemConfig {
    pub elites: usize,
    /// α, as CEM's.
    pub momentum: f64,
    /// Iteration i samples ⌈max(population·decay^(−i), 2·elites)⌉ (mbrl-lib: 1.3).
    pub decay: f64,
    /// β: the samples' power spectrum ∝ f^(−β) along time (mbrl-lib: 2).
    pub colored_noise: f64,
    /// The share of elites (rounded up) carried on (mbrl-lib: 0.3).
    pub keep_elites: f64,
}

/// Model-predictive path integral control (mbrl-lib's `MPPIOptimizer`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MppiConfig {
    /// Candidates weigh exp((R − max R) / temperature): lower is greedier.
    pub temperature: f64,
    /// β: each sampled action is β·(mean + noise) + (1 − β)·the one before
    /// (mbrl-lib: 0.9); 1 samples every step independently.
    pub smoothing: f64,
}

/// A planner's sizes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlanBudget {
    pub horizon: usize,
    pub population: usize,
    pub iterations: usize,
    pub particles: usize,
}

impl PlanBudget {
    /// mbrl-lib's PETS on hopper (`pets_hopper`).
    pub const PETS_HOPPER: Self = Self {
        horizon: 30,
        population: 350,
        iterations: 5,
        particles: 20,
    };
    /// mbrl-lib's iCEM (`pets_icem_cartpole`).
    pub const ICEM: Self = Self {
        horizon: 10,
        population: 200,
        iterations: 5,
        particles: 20,
    };
    /// `nuno-trainer evaluate --planner`'s default: PETS' search with one
    /// particle, since 20 cost 20× per control step, and a 1000-step episode
    /// replans 1000 times.
    pub const MPC: Self = Self {
        particles: 1,
        ..Self::PETS_HOPPER
    };
}

/// Everything one planning call needs besides the model and the start.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanConfig {
    pub optimizer: Optimizer,
    /// Candidates sampled per iteration.
    pub population: usize,
    pub iterations: usize,
    /// The sampling standard deviation, as a share of each action's half-range
    /// (CEM's initial (high − low)/4 is 0.5; MPPI's σ = 1 on a ±1 box is 1).
    pub noise: f64,
    /// How candidates are rolled and scored: horizon, particles, discount,
    /// λ on η, the CVaR's α (when given, the objective is the CVaR of the
    /// return less λ times the mean accumulated η), ε(H, α).
    pub score: ScoreConfig,
}

/// A planning call's answer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Plan {
    /// `[H, act_dim]`, row-major: the first row is the action to take now.
    pub actions: Vec<f32>,
    /// The plan's own score, scored once more after the last iteration.
    pub score: CandidateScore,
    /// What the planner maximised, for the plan.
    pub objective: f64,
    /// iCEM's last elites, `[k, H, act_dim]`, for the next control step
    /// ([`PlanStart::elites`]); empty for the other planners.
    pub elites: Vec<f32>,
}

/// Where one planning call starts.
#[derive(Debug, Clone, Copy)]
pub struct PlanStart<'a> {
    /// The state, `[obs_dim]`.
    pub state: &'a [f32],
    /// `(low, high)` of each action.
    pub action_box: &'a [(f32, f32)],
    /// The previous control step's plan, `[H, act_dim]`: shifted one step
    /// here (mbrl-lib's `keep_last_solution`), it seeds the search.
    pub warm: Option<&'a [f32]>,
    /// The previous call's [`Plan::elites`]: iCEM's first iteration samples
    /// some of them shifted one step; the other planners ignore them.
    pub elites: &'a [f32],
}

/// Plans from `start` in the model.
pub fn plan(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    start: &PlanStart,
    config: &PlanConfig,
    rng: &mut ChaCha8Rng,
    cancel: &Cancel,
) -> Result<Plan, PlanningError> {
    let PlanStart {
        state,
        action_box,
        warm,
        elites,
    } = *start;
    check(config, action_box, warm, dynamics.act_dim())?;
    let problem = Problem {
        dynamics,
        rules,
        start: state,
        action_box,
        config,
    };
    let (actions, elites) = match config.optimizer {
        Optimizer::Cem(cem) => (problem.cem(&cem, warm, rng, cancel)?, Vec::new()),
        Optimizer::Icem(icem) => problem.icem(&icem, warm, elites, rng, cancel)?,
        Optimizer::Mppi(mppi) => (problem.mppi(&mppi, warm, rng, cancel)?, Vec::new()),
    };
    let scores = problem.score(&actions, 1, rng, cancel)?;
    Ok(Plan {
        objective: objective(&scores[0], &config.score),
        score: scores[0],
        actions,
        elites,
    })
}

/// What a planner maximises for one candidate: its η-penalised return, or
/// with a CVaR α the CVaR of its return less λ·(its mean accumulated η).
pub fn objective(score: &CandidateScore, config: &ScoreConfig) -> f64 {
    let value = match score.cvar_return {
        Some(cvar) => cvar - config.penalty * score.accumulated_eta,
        None => score.penalized_return,
    };
    // A diverged candidate ranks below every finite one.
    if value.is_nan() {
        f64::NEG_INFINITY
    } else {
        value
    }
}

/// `plan` shifted one step earlier, its last row `fill`.
pub fn shifted(plan: &[f32], act_dim: usize, fill: &[f32]) -> Vec<f32> {
    let mut out = plan[act_dim..].to_vec();
    out.extend_from_slice(fill);
    out
}

struct Problem<'a> {
    dynamics: &'a dyn BatchDynamics,
    rules: &'a Rules,
    start: &'a [f32],
    action_box: &'a [(f32, f32)],
    config: &'a PlanConfig,
}

impl Problem<'_> {
    fn score(
        &self,
        sequences: &[f32],
        count: usize,
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<Vec<CandidateScore>, PlanningError> {
        let candidates = Candidates {
            starts: self.start,
            sequences,
            per_start: count,
        };
        let config = &self.config.score;
        score_sequences(self.dynamics, self.rules, &candidates, config, rng, cancel)
    }

    /// The objective of each sequence in `sequences`, `[count, H, act_dim]`.
    fn objectives(
        &self,
        sequences: &[f32],
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<Vec<f64>, PlanningError> {
        let count = sequences.len() / (self.config.score.horizon * self.action_box.len());
        let scores = self.score(sequences, count, rng, cancel)?;
        Ok(scores
            .iter()
            .map(|s| objective(s, &self.config.score))
            .collect())
    }

    /// Each action's low and high, repeated over the horizon.
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let steps = self.config.score.horizon;
        let per_step = self
            .action_box
            .iter()
            .map(|&(l, h)| (f64::from(l), f64::from(h)));
        per_step.cycle().take(steps * self.action_box.len()).unzip()
    }

    /// The search's first mean: the warm plan shifted (its last row the
    /// box's middle), else the middle throughout; and the first variance.
    fn first_mean_and_variance(&self, warm: Option<&[f32]>) -> (Vec<f64>, Vec<f64>) {
        let (low, high) = self.bounds();
        let middle: Vec<f32> = (self.action_box.iter())
            .map(|&(l, h)| (l + h) / 2.0)
            .collect();
        let mean: Vec<f64> = match warm {
            Some(plan) => shifted(plan, middle.len(), &middle),
            None => middle.repeat(self.config.score.horizon),
        }
        .into_iter()
        .map(f64::from)
        .collect();
        let spread = |i: usize| self.config.noise * (high[i] - low[i]) / 2.0;
        let variance = (0..mean.len()).map(|i| spread(i).powi(2)).collect();
        (mean, variance)
    }

    /// mbrl-lib's CEM: a truncated normal around μ (start: the warm plan
    /// shifted, else the box's middle), its variance kept within half the
    /// distance to the bounds; μ and the variance refitted to the elites.
    fn cem(
        &self,
        cem: &CemConfig,
        warm: Option<&[f32]>,
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<Vec<f32>, PlanningError> {
        let (low, high) = self.bounds();
        let (mut mean, mut variance) = self.first_mean_and_variance(warm);
        let width = mean.len();
        for _ in 0..self.config.iterations {
            let population: Vec<f32> = (0..self.config.population)
                .flat_map(|_| {
                    (0..width)
                        .map(|i| {
                            let room = ((mean[i] - low[i]) / 2.0).min((high[i] - mean[i]) / 2.0);
                            let std = variance[i].min(room.powi(2)).sqrt();
                            (mean[i] + std * truncated_normal(rng)) as f32
                        })
                        .collect::<Vec<_>>()
                })
                .collect();
            let values = self.objectives(&population, rng, cancel)?;
            let elites = best(&values, cem.elites);
            for i in 0..width {
                let column: Vec<f64> = (elites.iter())
                    .map(|&e| f64::from(population[e * width + i]))
                    .collect();
                let (m, v) = mean_and_unbiased_variance(&column);
                mean[i] = cem.momentum * mean[i] + (1.0 - cem.momentum) * m;
                variance[i] = cem.momentum * variance[i] + (1.0 - cem.momentum) * v;
            }
        }
        Ok(mean.into_iter().map(|m| m as f32).collect())
    }

    /// mbrl-lib's iCEM: CEM's refit (the elites' biased variance) over
    /// samples μ + σ·coloured noise clipped to the box, from a population that
    /// decays each iteration; the first iteration adds some of the previous
    /// call's elites shifted one step (their last step drawn from N(μ, σ) of
    /// the last step), the middle ones some of the previous iteration's, the
    /// last one μ itself. Returns μ and the last elites.
    fn icem(
        &self,
        icem: &IcemConfig,
        warm: Option<&[f32]>,
        previous_call: &[f32],
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<(Vec<f32>, Vec<f32>), PlanningError> {
        let (low, high) = self.bounds();
        let (mut mean, mut variance) = self.first_mean_and_variance(warm);
        let (act_dim, horizon) = (self.action_box.len(), self.config.score.horizon);
        let width = mean.len();
        let noise = ColoredNoise::new(icem.colored_noise, horizon);
        let keep = (icem.keep_elites * icem.elites as f64).ceil() as usize;
        let mut elites: Vec<f32> = previous_call.to_vec();
        let last = self.config.iterations - 1;
        for i in 0..=last {
            let decayed = self.config.population as f64 * icem.decay.powi(-(i as i32));
            let size = (decayed.ceil() as usize).max(2 * icem.elites);
            // ν is drawn [size, act_dim, H] and read as [size, H, act_dim] (mbrl-lib's transpose).
            let nu = noise.sample(size * act_dim, rng);
            let mut population: Vec<f32> = (0..size * width)
                .map(|at| {
                    let (c, j) = (at / width, at % width);
                    let (t, a) = (j / act_dim, j % act_dim);
                    let sample = mean[j] + variance[j].sqrt() * nu[(c * act_dim + a) * horizon + t];
                    sample.clamp(low[j], high[j]) as f32
                })
                .collect();
            let carried = elites.len() / width;
            if i == 0 && carried > 0 {
                for e in pick(carried, keep, rng) {
                    let elite = &elites[e * width..(e + 1) * width];
                    let fill: Vec<f32> = (width - act_dim..width)
                        .map(|j| {
                            let x: f64 = rng.sample(StandardNormal);
                            (mean[j] + variance[j].sqrt() * x) as f32
                        })
                        .collect();
                    population.extend(shifted(elite, act_dim, &fill));
                }
            } else if i == last && i > 0 {
                population.extend(mean.iter().map(|&m| m as f32));
            } else if carried > 0 {
                for e in pick(carried, keep, rng) {
                    population.extend_from_slice(&elites[e * width..(e + 1) * width]);
                }
            }
            let values = self.objectives(&population, rng, cancel)?;
            let best = best(&values, icem.elites);
            elites = (best.iter())
                .flat_map(|&e| population[e * width..(e + 1) * width].iter().copied())
                .collect();
            for j in 0..width {
                let column: Vec<f64> = (0..best.len())
                    .map(|e| f64::from(elites[e * width + j]))
                    .collect();
                let (m, v) = mean_and_biased_variance(&column);
                mean[j] = icem.momentum * mean[j] + (1.0 - icem.momentum) * m;
                variance[j] = icem.momentum * variance[j] + (1.0 - icem.momentum) * v;
            }
        }
        Ok((mean.into_iter().map(|m| m as f32).collect(), elites))
    }

    /// mbrl-lib's MPPI: the mean (the warm plan shifted, its last row kept;
    /// else zero) plus smoothed truncated-normal noise, clipped to the box,
    /// reweighted by exp((R − max R)/temperature) each iteration.
    fn mppi(
        &self,
        mppi: &MppiConfig,
        warm: Option<&[f32]>,
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<Vec<f32>, PlanningError> {
        let act_dim = self.action_box.len();
        let (low, high) = self.bounds();
        let (mut mean, previous): (Vec<f64>, Vec<f64>) = match warm {
            Some(plan) => {
                let last = &plan[plan.len() - act_dim..];
                let mean = shifted(plan, act_dim, last);
                (
                    mean.into_iter().map(f64::from).collect(),
                    plan[..act_dim].iter().map(|&a| f64::from(a)).collect(),
                )
            }
            None => (vec![0.0; low.len()], vec![0.0; act_dim]),
        };
        let width = mean.len();
        let beta = mppi.smoothing;
        for _ in 0..self.config.iterations {
            let mut population = Vec::with_capacity(self.config.population * width);
            for _ in 0..self.config.population {
                let mut before = previous.clone();
                for i in 0..width {
                    let noise =
                        self.config.noise * (high[i] - low[i]) / 2.0 * truncated_normal(rng);
                    let a = beta * (mean[i] + noise) + (1.0 - beta) * before[i % act_dim];
                    before[i % act_dim] = a;
                    population.push(a.clamp(low[i], high[i]) as f32);
                }
            }
            let values = self.objectives(&population, rng, cancel)?;
            let top = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let weights: Vec<f64> = (values.iter())
                .map(|&r| ((r - top) / mppi.temperature).exp())
                .collect();
            let total: f64 = weights.iter().sum::<f64>() + 1e-10;
            for (i, m) in mean.iter_mut().enumerate() {
                let weighted: f64 = (weights.iter().enumerate())
                    .map(|(c, w)| w * f64::from(population[c * width + i]))
                    .sum();
                *m = weighted / total;
            }
        }
        Ok(mean.into_iter().map(|m| m as f32).collect())
    }
}

/// N(0, 1) resampled until within ±2 (mbrl-lib's `truncated_normal_`).
fn truncated_normal(rng: &mut ChaCha8Rng) -> f64 {
    loop {
        let x: f64 = rng.sample(StandardNormal);
        if x.abs() <= 2.0 {
            return x;
        }
    }
}

/// The indices of the `count` largest values, best first.
fn best(values: &[f64], count: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    order.truncate(count);
    order
}

/// `count` of `0..n` drawn without replacement (all of them when `count` ≥ `n`).
fn pick(n: usize, count: usize, rng: &mut ChaCha8Rng) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let count = count.min(n);
    for i in 0..count {
        let j = rng.random_range(i..n);
        order.swap(i, j);
    }
    order.truncate(count);
    order
}

fn mean_and_biased_variance(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (
        mean,
        values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n,
    )
}

fn mean_and_unbiased_variance(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let squares: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
    let variance = if values.len() > 1 {
        squares / (n - 1.0)
    } else {
        0.0
    };
    (mean, variance)
}

pub(super) fn check(
    config: &PlanConfig,
    action_box: &[(f32, f32)],
    warm: Option<&[f32]>,
    act_dim: usize,
) -> Result<(), PlanningError> {
    let invalid = |message: String| Err(PlanningError::Invalid(message));
    if config.population == 0 || config.iterations == 0 {
        return invalid("population and iterations must each be at least 1".into());
    }
    if !(config.noise.is_finite() && config.noise > 0.0) {
        return invalid(format!("noise {} is not a number > 0", config.noise));
    }
    if action_box.len() != act_dim || !action_box.iter().all(|&(l, h)| l < h) {
        return invalid(format!(
            "the action box needs {act_dim} intervals of low < high"
        ));
    }
    let width = config.score.horizon * act_dim;
    if let Some(plan) = warm
        && plan.len() != width
    {
        return invalid(format!(
            "the warm start holds {} values, not horizon × act_dim = {width}",
            plan.len()
        ));
    }
    match config.optimizer {
        Optimizer::Cem(CemConfig { elites, momentum })
        | Optimizer::Icem(IcemConfig {
            elites, momentum, ..
        }) => {
            if elites == 0 || elites > config.population {
                return invalid(format!(
                    "elites {elites} is not between 1 and the population {}",
                    config.population
                ));
            }
            if !(0.0..1.0).contains(&momentum) {
                return invalid(format!("momentum {momentum} is not in [0, 1)"));
            }
            if let Optimizer::Icem(icem) = config.optimizer {
                check_icem(&icem)?;
            }
        }
        Optimizer::Mppi(mppi) => {
            if !(mppi.temperature.is_finite() && mppi.temperature > 0.0) {
                return invalid(format!(
                    "temperature {} is not a number > 0",
                    mppi.temperature
                ));
            }
            if !(mppi.smoothing > 0.0 && mppi.smoothing <= 1.0) {
                return invalid(format!("smoothing {} is not in (0, 1]", mppi.smoothing));
            }
        }
    }
    Ok(())
}

fn check_icem(icem: &IcemConfig) -> Result<(), PlanningError> {
    let invalid = |message: String| Err(PlanningError::Invalid(message));
    if !(icem.decay.is_finite() && icem.decay >= 1.0) {
        return invalid(format!("decay {} is not a number ≥ 1", icem.decay));
    }
    if !(icem.colored_noise.is_finite() && icem.colored_noise >= 0.0) {
        return invalid(format!(
            "colored_noise {} is not a number ≥ 0",
            icem.colored_noise
        ));
    }
    if !(0.0..=1.0).contains(&icem.keep_elites) {
        return invalid(format!("keep_elites {} is not in [0, 1]", icem.keep_elites));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shifted_plan_drops_its_first_step_and_ends_in_the_fill() {
        let plan = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        assert_eq!(
            shifted(&plan, 2, &[0.0, -1.0]),
            [3.0, 4.0, 5.0, 6.0, 0.0, -1.0]
        );
    }

    #[test]
    fn elites_are_the_best_and_their_variance_is_unbiased() {
        assert_eq!(best(&[0.5, f64::NEG_INFINITY, 3.0, 1.0], 2), [2, 3]);
        // Mean 2; squares 1 + 0 + 1 over n − 1 = 2.
        assert_eq!(mean_and_unbiased_variance(&[1.0, 2.0, 3.0]), (2.0, 1.0));
    }
}

//! The rollout behind scores, without a trace: each particle keeps running
//! sums (its discounted and penalised returns, η's sum and maximum, how it
//! ended) instead of every state it passed, and several callers' candidates
//! share each step's one model call. Each group draws its rows' noise from
//! its own generator in the order it would alone, so its scores are the
//! same, bit for bit, batched with others or not: the networks' rows do not
//! depend on one another.

use std::ops::Range;

use rand_chacha::ChaCha8Rng;

use super::PlanningError;
use super::score::{CandidateScore, Candidates, ScoreConfig, check, score_particles};
use crate::agent::{StepOutcome, judge_row};
use crate::envs::Rules;
use crate::shared::{BatchDynamics, Cancel, Cancelled, scaled_noise};

/// One caller's candidates, settings, noise and cancel flag.
pub struct ScoreGroup<'a> {
    pub candidates: Candidates<'a>,
    pub config: &'a ScoreConfig,
    pub rng: &'a mut ChaCha8Rng,
    pub cancel: &'a Cancel,
}

/// One particle's running sums along the steps it kept.
#[derive(Debug, Clone, Copy)]
pub(super) struct Tally {
    /// Σ γ^t r_t (with the caller's cost terms).
    pub discounted_return: f64,
    /// Σ γ^t (r_t − λ·η_t).
    pub penalized_return: f64,
    /// γ^t of the next kept step.
    weight: f64,
    /// Σ η_t over the kept steps.
    pub eta_sum: f64,
    /// The largest η of any step taken, a truncating one included.
    pub max_eta: f64,
    pub kept: usize,
    pub outcome: StepOutcome,
}

impl Tally {
    const START: Self = Self {
        discounted_return: 0.0,
        penalized_return: 0.0,
        weight: 1.0,
        eta_sum: 0.0,
        max_eta: 0.0,
        kept: 0,
        outcome: StepOutcome::Continued,
    };

    fn keep(&mut self, reward: f64, eta: f32, config: &ScoreConfig) {
        self.discounted_return += self.weight * reward;
        self.penalized_return += self.weight * (reward - config.penalty * f64::from(eta));
        self.weight *= config.discount;
        self.eta_sum += f64::from(eta);
        self.kept += 1;
    }
}

/// Where a rollout row comes from: its group, and where its candidate's
/// actions begin in that group's sequences.
#[derive(Debug, Clone, Copy)]
struct Row {
    group: usize,
    actions_at: usize,
}

/// Scores every group's candidates (see [`score_sequences`](super::score_sequences)),
/// all groups' rows in one model call per step. A group whose shapes or
/// settings are wrong, or whose flag is set before it ends, gets its error
/// and takes no further part; the others go on.
pub fn score_groups(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    mut groups: Vec<ScoreGroup>,
) -> Vec<Result<Vec<CandidateScore>, PlanningError>> {
    let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
    let mut failed: Vec<Option<PlanningError>> = (groups.iter())
        .map(|g| {
            let c = &g.candidates;
            check(
                c.starts,
                c.sequences,
                c.per_start,
                g.config,
                (obs_dim, act_dim),
            )
            .err()
        })
        .collect();
    let (mut observations, rows, spans) = tile(dynamics, &groups, &failed);
    let mut tallies = vec![Tally::START; rows.len()];
    let mut accumulated = vec![0.0f32; rows.len()];
    let mut active: Vec<usize> = (0..rows.len()).collect();
    let mut k = 0;
    while !active.is_empty() {
        for (g, group) in groups.iter().enumerate() {
            if failed[g].is_none() && group.cancel.is_cancelled() {
                failed[g] = Some(PlanningError::Cancelled(Cancelled));
            }
        }
        active.retain(|&r| failed[rows[r].group].is_none());
        let step = Step {
            dynamics,
            rules,
            rows: &rows,
            k,
        };
        active = step.run(
            &mut groups,
            &active,
            &mut observations,
            &mut tallies,
            &mut accumulated,
        );
        k += 1;
    }
    (groups.iter().zip(failed).zip(spans))
        .map(|((group, failed), span)| match failed {
            Some(error) => Err(error),
            None => Ok((tallies[span].chunks_exact(group.config.particles))
                .map(|particles| score_particles(particles, group.config))
                .collect()),
        })
        .collect()
}

/// Every valid group's rows, in group order: each start once per candidate
/// and particle (particle p of candidate c is the group's row c·P + p), and
/// each group's span of rows.
fn tile(
    dynamics: &dyn BatchDynamics,
    groups: &[ScoreGroup],
    failed: &[Option<PlanningError>],
) -> (Vec<f32>, Vec<Row>, Vec<Range<usize>>) {
    let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
    let mut observations = Vec::new();
    let mut rows = Vec::new();
    let mut spans = Vec::with_capacity(groups.len());
    for (g, group) in groups.iter().enumerate() {
        let first = rows.len();
        if failed[g].is_some() {
            spans.push(first..first);
            continue;
        }
        let (c, config) = (&group.candidates, group.config);
        let sequence = config.horizon * act_dim;
        for (b, start) in c.starts.chunks_exact(obs_dim).enumerate() {
            for n in 0..c.per_start {
                for _ in 0..config.particles {
                    observations.extend_from_slice(start);
                    rows.push(Row {
                        group: g,
                        actions_at: (b * c.per_start + n) * sequence,
                    });
                }
            }
        }
        spans.push(first..rows.len());
    }
    (observations, rows, spans)
}

/// Step `k` of every active row.
struct Step<'a> {
    dynamics: &'a dyn BatchDynamics,
    rules: &'a Rules,
    rows: &'a [Row],
    k: usize,
}

impl Step<'_> {
    /// Steps the `active` rows once, tallies what each kept, and returns the
    /// rows that go on.
    fn run(
        &self,
        groups: &mut [ScoreGroup],
        active: &[usize],
        observations: &mut [f32],
        tallies: &mut [Tally],
        accumulated: &mut [f32],
    ) -> Vec<usize> {
        let dynamics = self.dynamics;
        let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
        let obs: Vec<f32> = (active.iter())
            .flat_map(|&r| &observations[r * obs_dim..(r + 1) * obs_dim])
            .copied()
            .collect();
        let actions: Vec<f32> = (active.iter())
            .flat_map(|&r| {
                let row = self.rows[r];
                let at = row.actions_at + self.k * act_dim;
                &groups[row.group].candidates.sequences[at..at + act_dim]
            })
            .copied()
            .collect();
        let noise = self.noise(groups, active);
        let step = dynamics.step(&dynamics.states_from_observations(&obs), &actions, &noise);
        let mut going_on = Vec::with_capacity(active.len());
        for (i, &r) in active.iter().enumerate() {
            let config = groups[self.rows[r].group].config;
            let from = (
                &obs[i * obs_dim..(i + 1) * obs_dim],
                &actions[i * act_dim..(i + 1) * act_dim],
            );
            // Planners score in the model as it is: no HALT, no box.
            let row = judge_row(
                dynamics,
                self.rules,
                &step,
                i,
                from,
                &mut accumulated[r],
                (config.threshold, None, None),
            );
            let tally = &mut tallies[r];
            tally.outcome = row.fate;
            if row.fate == StepOutcome::Diverged {
                continue;
            }
            tally.max_eta = tally.max_eta.max(f64::from(row.eta));
            if row.fate == StepOutcome::Truncated {
                continue;
            }
            tally.keep(
                config.cost.reward(row.reward, row.next_obs),
                row.eta,
                config,
            );
            observations[r * obs_dim..(r + 1) * obs_dim].copy_from_slice(row.next_obs);
            if row.fate == StepOutcome::Continued && self.k + 1 < config.horizon {
                going_on.push(r);
            }
        }
        going_on
    }

    /// Each group's noise for its active rows, from its own generator, as it
    /// would draw it alone (a group's rows are consecutive in `active`).
    fn noise(&self, groups: &mut [ScoreGroup], active: &[usize]) -> Vec<f32> {
        let width = self.dynamics.noise_dim();
        let mut noise = Vec::with_capacity(active.len() * width);
        for run in active.chunk_by(|&a, &b| self.rows[a].group == self.rows[b].group) {
            let group = &mut groups[self.rows[run[0]].group];
            let scale = group.config.noise_scale;
            noise.extend(scaled_noise(run.len() * width, scale, group.rng));
        }
        noise
    }
}

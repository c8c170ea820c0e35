//! What `dataset check` reports of a dataset against the system file it is
//! said to log: its size, each column's range, and whether eq. 8's prior
//! (d position/dt = velocity) holds for every declared pair at the declared
//! dt, so a wrong `dt` or a wrong pair is caught before a fit.

use serde::Serialize;

use super::Dataset;
use crate::envs::SystemSpec;

/// Relative errors above this say the pair or dt is wrong rather than the
/// logging coarse: a dt off by a factor k leaves at least |1/k − 1| (0.2 at
/// k = 1.25 or 0.83), a wrong pair ≈ 1 or more, while the best of the three
/// velocities matches a finite difference far closer on any integrator
/// (the tutorial's pendulum: 0.002).
pub const PAIR_ERROR_LIMIT: f64 = 0.2;

/// One column's values over the dataset.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ColumnRange {
    pub name: String,
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub std: f64,
}

/// How well `(position' − position)/dt` matches the declared velocity, as
/// RMS(difference) / RMS(velocity) over every transition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairCheck {
    pub position: String,
    pub velocity: String,
    /// Against the velocity before the step.
    pub against_velocity: f64,
    /// Against the velocity after the step.
    pub against_next_velocity: f64,
    /// Against the mean of the two.
    pub against_mean_velocity: f64,
    /// The dt that best fits Δposition = dt · mean velocity (least squares):
    /// what the log says the step is, whatever the file declares.
    pub fitted_dt: f64,
}

impl PairCheck {
    /// The best of the three: which one holds depends on the integrator that
    /// logged the data (explicit, semi-implicit or trapezoidal).
    pub fn best(&self) -> f64 {
        self.against_velocity
            .min(self.against_next_velocity)
            .min(self.against_mean_velocity)
    }

    /// Whether the pair holds at the declared dt.
    pub fn holds(&self) -> bool {
        self.best() <= PAIR_ERROR_LIMIT
    }
}

/// Everything `dataset check` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SystemCheck {
    pub system: String,
    pub transitions: usize,
    pub episodes: usize,
    pub terminals: usize,
    pub observations: Vec<ColumnRange>,
    pub actions: Vec<ColumnRange>,
    /// Actions outside the declared box, per action column.
    pub actions_outside_box: Vec<usize>,
    pub pairs: Vec<PairCheck>,
}

impl SystemCheck {
    /// Whether every pair holds and every action lies in its box.
    pub fn passed(&self) -> bool {
        self.pairs.iter().all(PairCheck::holds) && self.actions_outside_box.iter().all(|&n| n == 0)
    }
}

/// Checks `dataset` (already of `system`'s widths) against `system`.
pub fn check_system(dataset: &Dataset, system: &SystemSpec) -> SystemCheck {
    let ranges = |values: &ndarray::Array2<f32>, names: &[String]| -> Vec<ColumnRange> {
        names
            .iter()
            .enumerate()
            .map(|(j, name)| column_range(name, values.column(j).iter().map(|&x| f64::from(x))))
            .collect()
    };
    let actions_outside_box = (0..system.act_dim())
        .map(|j| {
            let (low, high) = (system.action_low[j] as f32, system.action_high[j] as f32);
            (dataset.actions.column(j).iter())
                .filter(|&&a| !(low..=high).contains(&a))
                .count()
        })
        .collect();
    let split = &system.split;
    let pairs = (split.positions.iter().zip(&split.position_velocity))
        .map(|(&p, &v)| pair_check(dataset, system, p, v))
        .collect();
    SystemCheck {
        system: system.name.clone(),
        transitions: dataset.len(),
        episodes: dataset.trajectories().len(),
        terminals: dataset.terminals.iter().filter(|&&t| t).count(),
        observations: ranges(&dataset.observations, &system.observations),
        actions: ranges(&dataset.actions, &system.actions),
        actions_outside_box,
        pairs,
    }
}

fn column_range(name: &str, values: impl Iterator<Item = f64> + Clone) -> ColumnRange {
    let n = values.clone().count().max(1) as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.clone().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    ColumnRange {
        name: name.to_string(),
        min: values.clone().fold(f64::INFINITY, f64::min),
        max: values.fold(f64::NEG_INFINITY, f64::max),
        mean,
        std: var.sqrt(),
    }
}

/// Position `p` against velocity `v` over every transition; an angle's
/// difference is wrapped to (−π, π], so a logged angle that wraps around
/// does not read as a jump.
fn pair_check(dataset: &Dataset, system: &SystemSpec, p: usize, v: usize) -> PairCheck {
    let angle = system.split.angles.contains(&p);
    let (mut before, mut after, mut mean, mut scale) = (0.0, 0.0, 0.0, 0.0);
    let (mut change_by_velocity, mut velocity_squared) = (0.0, 0.0);
    for i in 0..dataset.len() {
        let (s, s_next) = (
            dataset.observations.row(i),
            dataset.next_observations.row(i),
        );
        let mut change = f64::from(s_next[p]) - f64::from(s[p]);
        if angle {
            change = wrap_angle(change);
        }
        let rate = change / system.dt;
        let (v0, v1) = (f64::from(s[v]), f64::from(s_next[v]));
        before += (rate - v0).powi(2);
        after += (rate - v1).powi(2);
        let v_mean = 0.5 * (v0 + v1);
        mean += (rate - v_mean).powi(2);
        scale += v0.powi(2);
        change_by_velocity += change * v_mean;
        velocity_squared += v_mean * v_mean;
    }
    // A velocity that is zero throughout makes any change infinitely wrong.
    let relative = |sum: f64| (sum / scale.max(f64::MIN_POSITIVE)).sqrt();
    PairCheck {
        position: system.observations[p].clone(),
        velocity: system.observations[v].clone(),
        against_velocity: relative(before),
        against_next_velocity: relative(after),
        against_mean_velocity: relative(mean),
        fitted_dt: change_by_velocity / velocity_squared.max(f64::MIN_POSITIVE),
    }
}

/// `x` wrapped to (−π, π].
fn wrap_angle(x: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let wrapped = (x + PI).rem_euclid(TAU) - PI;
    if wrapped == -PI { PI } else { wrapped }
}

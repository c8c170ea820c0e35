//! The model analyses (Figures 3–5) against hand computations on models with
//! known answers: a model that predicts no change, one whose uncertainty is
//! the action's norm, and the real task stepped here.

use nuno::agent::{PortableActor, StateBox};
use nuno::data::{Dataset, GenerateConfig, WindowSampler, generate};
use nuno::envs::{MujocoTask, Rules, TaskConfig, TaskName, TaskRules};
use nuno::experiment::{
    ActionSource, ExploitationConfig, PredictionConfig, exploitation, prediction_error,
    uncertainty_by_action,
};
use nuno::shared::{BatchDynamics, BatchPolicy, BatchShape, ModelStep};

/// s' = s (no change), σ = 0, η = ‖a‖₂.
struct Stationary;

impl BatchDynamics for Stationary {
    fn shape(&self) -> BatchShape {
        BatchShape {
            obs_dim: 11,
            act_dim: 3,
            learns_reward: false,
            dt: 0.008,
        }
    }
    fn step(&self, states: &[f32], actions: &[f32], _noise: &[f32]) -> ModelStep {
        let n = states.len() / 11;
        ModelStep {
            next_states: states.to_vec(),
            means: states.to_vec(),
            sigma: vec![0.0; n * 11],
            h_eta: vec![0.0; n * 11],
            eta: actions
                .chunks_exact(3)
                .map(|a| a.iter().map(|x| x * x).sum::<f32>().sqrt())
                .collect(),
            truncation_signal: None,
        }
    }
}

struct Constant(Vec<f32>);

impl BatchPolicy for Constant {
    fn obs_dim(&self) -> usize {
        11
    }
    fn act_dim(&self) -> usize {
        3
    }
    fn act(&self, observations: &[f32], _rng: &mut dyn rand::RngCore) -> Vec<f32> {
        self.0.repeat(observations.len() / 11)
    }
}

fn task() -> TaskConfig {
    TaskConfig::d4rl(TaskName::Hopper)
}

fn data() -> Dataset {
    let policy = PortableActor::rlkit_random(11, 3, &[32, 32], 3);
    generate(
        &GenerateConfig::new(task(), "random", 3000, 3),
        &policy,
        "test",
        &|_| {},
    )
    .unwrap()
}

#[test]
fn prediction_error_of_a_no_change_model_is_the_datas_own_drift() {
    let data = data();
    let rules = Rules::from(TaskRules::of_task(&task()).unwrap());
    let scale = nuno::data::Stats::fit(data.observations.view(), &Default::default()).std;
    let horizon = 5;
    let config = PredictionConfig {
        horizon,
        windows: 1_000_000,
        particles: 2,
        seed: 0,
    };
    let error = prediction_error(&Stationary, &rules, &data, &scale, &config).unwrap();
    // By hand: every non-overlapping window, s_t against s_{t+k+1}.
    let starts = WindowSampler::non_overlapping(&data, horizon)
        .unwrap()
        .starts()
        .to_vec();
    let column_std = |d: usize| {
        let column: Vec<f64> = data
            .observations
            .column(d)
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        let mean = column.iter().sum::<f64>() / column.len() as f64;
        (column.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / column.len() as f64).sqrt()
    };
    for k in 0..horizon {
        let mut sum = 0.0;
        for &t in &starts {
            for d in 0..11 {
                let change =
                    f64::from(data.next_observations[[t + k, d]] - data.observations[[t, d]]);
                sum += (change / column_std(d)).powi(2) / 11.0;
            }
        }
        let expected = (sum / starts.len() as f64).sqrt();
        assert_eq!(error.windows[k], starts.len());
        assert!(
            (error.rmse[k] / expected - 1.0).abs() < 1e-4,
            "step {}: {} vs {expected}",
            k + 1,
            error.rmse[k]
        );
    }
    assert!(
        error.rmse[4] > error.rmse[0],
        "a no-change model drifts from the data"
    );
}

#[test]
fn uncertainty_is_probed_at_dataset_random_and_policy_actions() {
    let data = data();
    let policy = Constant(vec![0.5, -0.5, 0.25]);
    let probes = uncertainty_by_action(
        &Stationary,
        &data,
        Some(&policy),
        &[(-1.0, 1.0); 3],
        4000,
        1,
    );
    let sources: Vec<ActionSource> = probes.iter().map(|(s, _)| *s).collect();
    assert_eq!(
        sources,
        [
            ActionSource::Dataset,
            ActionSource::Random,
            ActionSource::Policy
        ]
    );
    for (_, eta) in &probes {
        assert_eq!(eta.len(), 3000, "4000 asked of 3000 transitions");
        assert!(eta.windows(2).all(|w| w[0] <= w[1]), "sorted");
    }
    // E‖U‖ for U uniform on [−1, 1]³ is 0.9607 (a known constant).
    let random = &probes[1].1;
    let mean = random.iter().map(|&x| f64::from(x)).sum::<f64>() / random.len() as f64;
    assert!((mean - 0.9607).abs() < 0.02, "mean ‖U‖ {mean}");
    assert!(
        probes[2].1.iter().all(|&e| (e - 0.75).abs() < 1e-6),
        "‖(.5, −.5, .25)‖ = .75"
    );
}

#[test]
fn exploitation_compares_the_real_task_with_the_model_and_its_penalty() {
    // Actions exact in f32, so the task gets the same numbers from both.
    let policy = Constant(vec![0.25, -0.125, 0.5]);
    let rules = Rules::from(TaskRules::of_task(&task()).unwrap());
    let config = ExploitationConfig {
        starts: 3,
        horizon: 40,
        penalty: 2.0,
        seed: 5,
    };
    // The data's range: wide, but for the height (obs[0]) cut at the middle
    // start's, and the x velocity (obs[5]) at 0.5 m/s.
    let mut env = MujocoTask::new(&task()).unwrap();
    let mut heights: Vec<f32> = (0..3).map(|i| env.reset(Some(5 + i))[0] as f32).collect();
    heights.sort_by(f32::total_cmp);
    let (mut lower, mut upper) = (vec![-1e3f32; 11], vec![1e3f32; 11]);
    (upper[0], upper[5]) = (heights[1], 0.5);
    lower[5] = -0.5;
    let data = StateBox {
        lower: lower.clone(),
        upper: upper.clone(),
    };
    let result = exploitation((&Stationary, &rules), &task(), &policy, &data, &config).unwrap();
    // The real task by hand from the same resets.
    let inside = |obs: &[f64]| {
        (obs.iter().zip(lower.iter().zip(&upper)))
            .all(|(&x, (&low, &high))| f64::from(low) <= x && x <= f64::from(high))
    };
    let mut per_step = vec![0.0f64; 40];
    let mut outside = vec![(0usize, 0usize); 40];
    for i in 0..3 {
        env.reset(Some(5 + i));
        for (r, (took, out)) in per_step.iter_mut().zip(&mut outside) {
            let step = env.step(&[0.25, -0.125, 0.5]).unwrap();
            *r += step.reward / 3.0;
            let obs: Vec<f64> = step
                .observation
                .iter()
                .map(|&x| f64::from(x as f32))
                .collect();
            (*took, *out) = (*took + 1, *out + usize::from(!inside(&obs)));
            if step.terminated {
                break;
            }
        }
    }
    for (k, &(took, out)) in outside.iter().enumerate() {
        let share = result.real_outside_data[k];
        match took {
            0 => assert!(share.is_nan(), "step {}: {share}", k + 1),
            _ => assert_eq!(share, out as f64 / took as f64, "step {}", k + 1),
        }
    }
    // Both kinds of step occur (the check above compares something).
    let shares = &result.real_outside_data;
    assert!(
        shares.contains(&0.0) && shares.iter().any(|&s| s > 0.0),
        "{shares:?}"
    );
    // The model never moves: the tallest start stays above the cut, alone.
    assert!(result.model_outside_data.iter().all(|&s| s == 1.0 / 3.0));
    let mut total = 0.0;
    for (k, r) in per_step.iter().enumerate() {
        total += r;
        assert!((result.real[k] - total).abs() < 1e-9, "step {}", k + 1);
    }
    // A model that never moves: every step the reward of its start's observed
    // x velocity (obs[5]) + the healthy bonus 1 − 1e-3·‖a‖², minus λ·‖a‖ when
    // penalised, averaged over the starts.
    let a2 = 0.0625 + 0.015625 + 0.25;
    let eta = f64::from((a2 as f32).sqrt());
    let velocity = (0..3).map(|i| env.reset(Some(5 + i))[5] / 3.0).sum::<f64>();
    for k in 0..40 {
        let steps = (k + 1) as f64;
        let reward = velocity + 1.0 - 1e-3 * a2;
        assert!(
            (result.model[k] - steps * reward).abs() < 1e-4,
            "step {}",
            k + 1
        );
        assert!(
            (result.model_penalized[k] - steps * (reward - 2.0 * eta)).abs() < 1e-4,
            "step {}",
            k + 1
        );
    }
}

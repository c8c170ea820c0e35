//! Scoring candidate action sequences (`planning::score_sequences`) against
//! hand computations on a point mass whose every step is known: returns,
//! their discount and η's penalty, termination, ε's truncation, and the CVaR
//! over particles.

use std::path::Path;
use std::sync::Arc;

use nuno::envs::{Rules, SystemSpec};
use nuno::planning::{
    CandidateScore, Candidates, CemConfig, Cost, CostTerm, MppiConfig, Optimizer, Plan, PlanConfig,
    PlanStart, ScoreConfig, plan, score_sequences,
};
use nuno::shared::{BatchDynamics, BatchShape, Cancel, ModelStep};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// x′ = x + u + noise, η = |x| before the step.
struct PointMass;

impl BatchDynamics for PointMass {
    fn shape(&self) -> BatchShape {
        BatchShape {
            obs_dim: 1,
            act_dim: 1,
            learns_reward: false,
            dt: 1.0,
        }
    }
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let next: Vec<f32> = (0..states.len())
            .map(|i| states[i] + actions[i] + noise[i])
            .collect();
        ModelStep {
            means: next.clone(),
            next_states: next,
            sigma: vec![1.0; states.len()],
            h_eta: vec![0.0; states.len()],
            eta: states.iter().map(|x| x.abs()).collect(),
            truncation_signal: None,
        }
    }
}

/// The reward is the position reached; an episode ends outside [−5, 5].
fn rules() -> Rules {
    let text = "name = \"point\"\ndt = 1.0\nobservations = [\"x\"]\nactions = [\"u\"]\n\
                action_low = [-10.0]\naction_high = [10.0]\n\
                [reward]\nexpression = \"next_x\"\n\
                [termination]\nbounds = { x = [-5.0, 5.0] }\n";
    Rules::System(Arc::new(
        SystemSpec::parse(text, Path::new("point.toml")).unwrap(),
    ))
}

fn config(threshold: Option<f32>) -> ScoreConfig {
    ScoreConfig {
        horizon: 3,
        particles: 2,
        discount: 0.5,
        penalty: 0.1,
        cvar_alpha: None,
        threshold,
        noise_scale: 0.0,
        cost: Cost::default(),
    }
}

/// Starts x = 0 and x = 1, two candidates each: [1, 1, 1] and [3, 3, 3]
/// from 0; [−1, −1, −1] and [0, 0, 0] from 1.
fn score(config: &ScoreConfig) -> Vec<CandidateScore> {
    let starts = [0.0, 1.0];
    let sequences = [
        1.0, 1.0, 1.0, 3.0, 3.0, 3.0, -1.0, -1.0, -1.0, 0.0, 0.0, 0.0,
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let cancel = Cancel::default();
    let candidates = Candidates {
        starts: &starts,
        sequences: &sequences,
        per_start: 2,
    };
    score_sequences(&PointMass, &rules(), &candidates, config, &mut rng, &cancel).unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6
}

#[test]
fn scores_are_the_discounted_penalised_returns_worked_by_hand() {
    let scores = score(&config(None));
    assert_eq!(scores.len(), 4);
    // From 0 by [1, 1, 1]: x = 1, 2, 3, η = 0, 1, 2: 1 + ½·2 + ¼·3 = 2.75;
    // penalised 1 + ½·1.9 + ¼·2.8 = 2.65.
    let s = scores[0];
    assert!(
        close(s.mean_return, 2.75) && close(s.penalized_return, 2.65),
        "{s:?}"
    );
    assert!(
        close(s.accumulated_eta, 3.0) && close(s.max_eta, 2.0),
        "{s:?}"
    );
    assert_eq!(
        (s.terminated, s.truncated_at, s.cvar_return),
        (0.0, None, None)
    );
    // From 0 by [3, 3, 3]: x = 3, then 6 leaves [−5, 5]: that step is its
    // last, kept as terminal: 3 + ½·6 = 6.
    let s = scores[1];
    assert!(
        close(s.mean_return, 6.0) && close(s.accumulated_eta, 3.0),
        "{s:?}"
    );
    assert_eq!(s.terminated, 1.0);
    // From 1 by [−1, −1, −1]: x = 0, −1, −2: 0 − ½ − ½ = −1; η = 1, 0, 1.
    let s = scores[2];
    assert!(close(s.mean_return, -1.0) && close(s.max_eta, 1.0), "{s:?}");
    assert!(close(s.penalized_return, -0.1 - 0.5 - 0.25 * 2.1), "{s:?}");
    // From 1 by [0, 0, 0]: x stays 1: 1 + ½ + ¼; penalised 0.9 · 1.75.
    let s = scores[3];
    assert!(
        close(s.mean_return, 1.75) && close(s.penalized_return, 1.575),
        "{s:?}"
    );
}

#[test]
fn epsilon_truncates_before_the_step_that_passes_it() {
    let scores = score(&config(Some(2.5)));
    // Accumulated η reaches 3 > 2.5 at step 2 (0, 1, 2): that step is
    // dropped, the return is what came before: 1 + ½·2.
    assert_eq!(scores[0].truncated_at, Some(2));
    assert!(close(scores[0].mean_return, 2.0), "{:?}", scores[0]);
    // From 0 by [3, 3, 3], η = 0, 3: truncated at step 1, before its fall.
    assert_eq!(scores[1].truncated_at, Some(1));
    assert_eq!(scores[1].terminated, 0.0);
    assert!(close(scores[1].mean_return, 3.0), "{:?}", scores[1]);
    assert_eq!(scores[2].truncated_at, None);
    assert_eq!(scores[3].truncated_at, Some(2));
}

#[test]
fn the_cvar_is_the_mean_of_the_worst_particles_returns() {
    let noisy = ScoreConfig {
        particles: 8,
        noise_scale: 1.0,
        cvar_alpha: Some(1.0),
        ..config(None)
    };
    let all = score(&noisy);
    let worst = score(&ScoreConfig {
        cvar_alpha: Some(0.25),
        ..noisy
    });
    for (all, worst) in all.iter().zip(&worst) {
        // The same seed gives the same particles.
        assert_eq!(all.mean_return, worst.mean_return);
        // α = 1 averages every particle; the worst quarter lies below.
        assert!(close(all.cvar_return.unwrap(), all.mean_return), "{all:?}");
        assert!(worst.cvar_return.unwrap() < all.mean_return, "{worst:?}");
    }
}

#[test]
fn mismatched_shapes_and_bad_settings_are_refused_by_name() {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let cancel = Cancel::default();
    let c = config(None);
    let run = |starts: &[f32], sequences: &[f32], config: &ScoreConfig, rng: &mut ChaCha8Rng| {
        let candidates = Candidates {
            starts,
            sequences,
            per_start: 2,
        };
        score_sequences(&PointMass, &rules(), &candidates, config, rng, &cancel)
            .unwrap_err()
            .to_string()
    };
    let error = run(&[0.0], &[1.0; 5], &c, &mut rng);
    assert!(
        error.contains("sequences hold 5 values") && error.contains("are 6"),
        "{error}"
    );
    let error = run(
        &[0.0],
        &[1.0; 6],
        &ScoreConfig {
            discount: 0.0,
            ..c.clone()
        },
        &mut rng,
    );
    assert!(error.contains("discount 0"), "{error}");
    let bad_alpha = ScoreConfig {
        cvar_alpha: Some(1.5),
        ..c.clone()
    };
    let error = run(&[0.0], &[1.0; 6], &bad_alpha, &mut rng);
    assert!(error.contains("cvar_alpha"), "{error}");
    let past = ScoreConfig {
        cost: Cost {
            terms: vec![CostTerm {
                dimension: 1,
                target: 0.0,
                weight: 1.0,
            }],
            replace_reward: false,
        },
        ..c
    };
    let error = run(&[0.0], &[1.0; 6], &past, &mut rng);
    assert!(
        error.contains("cost term 0: observation 1 is past the model's 1"),
        "{error}"
    );
}

#[test]
fn cost_terms_reward_the_targets_they_name_worked_by_hand() {
    let cost = |replace_reward| Cost {
        terms: vec![CostTerm {
            dimension: 0,
            target: 2.0,
            weight: 0.5,
        }],
        replace_reward,
    };
    let added = score(&ScoreConfig {
        cost: cost(false),
        ..config(None)
    });
    // From 0 by [1, 1, 1]: x = 1, 2, 3, each 1 from the target but the
    // middle: costs ½, 0, ½; rewards ½, 2, 2½: ½ + ½·2 + ¼·2½ = 2.125.
    assert!(close(added[0].mean_return, 2.125), "{:?}", added[0]);
    // η's penalty is as before: 0.1 · (0 + ½·1 + ¼·2).
    assert!(
        close(added[0].penalized_return, 2.125 - 0.1),
        "{:?}",
        added[0]
    );
    let replaced = score(&ScoreConfig {
        cost: cost(true),
        ..config(None)
    });
    // The costs alone: −½ + ½·0 − ¼·½.
    assert!(close(replaced[0].mean_return, -0.625), "{:?}", replaced[0]);
    // From 1 by [0, 0, 0]: x stays 1, cost ½ a step: −(½ + ¼ + ⅛).
    assert!(close(replaced[3].mean_return, -0.875), "{:?}", replaced[3]);
}

/// Reach x = 2 from 0 in three steps of |u| ≤ 1: reward −(x′ − 2)², so the
/// best plan is [1, 1, 0] (rewards −1, 0, 0), and every other loses more.
fn reach_rules() -> Rules {
    let text = "name = \"reach\"\ndt = 1.0\nobservations = [\"x\"]\nactions = [\"u\"]\n\
                action_low = [-1.0]\naction_high = [1.0]\n\
                [reward]\nexpression = \"0 - (next_x - 2)^2\"\n";
    Rules::System(Arc::new(
        SystemSpec::parse(text, Path::new("reach.toml")).unwrap(),
    ))
}

/// Three steps along the drift, undiscounted, no penalty: a plan's score is
/// the positions it reaches.
fn undiscounted_drift() -> ScoreConfig {
    ScoreConfig {
        particles: 1,
        discount: 1.0,
        penalty: 0.0,
        ..config(None)
    }
}

fn reach(optimizer: Optimizer, warm: Option<&[f32]>, seed: u64) -> Plan {
    let config = PlanConfig {
        optimizer,
        population: 200,
        iterations: 6,
        noise: match optimizer {
            Optimizer::Cem(_) => 0.5,
            Optimizer::Mppi(_) => 1.0,
        },
        score: undiscounted_drift(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let start = PlanStart {
        state: &[0.0],
        action_box: &[(-1.0, 1.0)],
        warm,
    };
    plan(
        &PointMass,
        &reach_rules(),
        &start,
        &config,
        &mut rng,
        &Cancel::default(),
    )
    .unwrap()
}

const CEM: Optimizer = Optimizer::Cem(CemConfig {
    elites: 20,
    momentum: 0.1,
});
const MPPI: Optimizer = Optimizer::Mppi(MppiConfig {
    temperature: 0.05,
    smoothing: 1.0,
});

#[test]
fn cem_and_mppi_find_the_plan_worked_by_hand() {
    for optimizer in [CEM, MPPI] {
        let plan = reach(optimizer, None, 7);
        // The first two actions push fully; the optimum's return is −1.
        assert!(
            plan.actions[0] > 0.9 && plan.actions[1] > 0.8,
            "{optimizer:?}: {plan:?}"
        );
        assert!(plan.objective > -1.1, "{optimizer:?}: {plan:?}");
        assert_eq!(plan.objective, plan.score.penalized_return);
        assert_eq!(
            reach(optimizer, None, 7),
            plan,
            "the same seed plans the same"
        );
    }
}

#[test]
fn a_warm_start_begins_from_the_previous_plan_shifted() {
    // One CEM iteration with every candidate an elite and all the old mean
    // kept (momentum → 1 is refused, so 0.999): the mean barely moves from
    // the warm plan [0.3, −0.4, 0.5] shifted to [−0.4, 0.5, 0] (the box's middle).
    let optimizer = Optimizer::Cem(CemConfig {
        elites: 200,
        momentum: 0.999,
    });
    let config = PlanConfig {
        optimizer,
        population: 200,
        iterations: 1,
        noise: 0.5,
        score: undiscounted_drift(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let warm = [0.3, -0.4, 0.5];
    let cancel = Cancel::default();
    let start = |warm| PlanStart {
        state: &[0.0],
        action_box: &[(-1.0, 1.0)],
        warm: Some(warm),
    };
    let plan = plan(
        &PointMass,
        &reach_rules(),
        &start(&warm),
        &config,
        &mut rng,
        &cancel,
    )
    .unwrap();
    for (got, want) in plan.actions.iter().zip([-0.4, 0.5, 0.0]) {
        assert!((got - want).abs() < 0.01, "{:?}", plan.actions);
    }
    let short = start(&warm[..2]);
    let bad = nuno::planning::plan(
        &PointMass,
        &reach_rules(),
        &short,
        &config,
        &mut rng,
        &cancel,
    )
    .unwrap_err();
    assert!(
        bad.to_string().contains("warm start holds 2 values"),
        "{bad}"
    );
}

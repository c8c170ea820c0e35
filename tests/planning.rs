//! Scoring candidate action sequences (`planning::score_sequences`) against
//! hand computations on a point mass whose every step is known: returns,
//! their discount and η's penalty, termination, ε's truncation, and the CVaR
//! over particles; against the model rollout's own trace; and several
//! callers' candidates scored in one loop as each alone.

use std::path::Path;
use std::sync::Arc;

use nuno::agent::{RolloutActions, RolloutConfig, StepOutcome, TruncatedStep, rollout_model};
use nuno::envs::{Rules, SystemSpec};
use nuno::planning::{
    CandidateScore, Candidates, CemConfig, Cost, CostTerm, IcemConfig, MppiConfig, Optimizer, Plan,
    PlanConfig, PlanStart, PlanningError, ScoreConfig, ScoreGroup, plan, score_groups,
    score_sequences,
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
            Optimizer::Cem(_) | Optimizer::Icem(_) => 0.5,
            Optimizer::Mppi(_) => 1.0,
        },
        score: undiscounted_drift(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let start = PlanStart {
        state: &[0.0],
        action_box: &[(-1.0, 1.0)],
        warm,
        elites: &[],
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
const ICEM: Optimizer = Optimizer::Icem(IcemConfig {
    elites: 20,
    momentum: 0.1,
    decay: 1.3,
    colored_noise: 2.0,
    keep_elites: 0.3,
});
const MPPI: Optimizer = Optimizer::Mppi(MppiConfig {
    temperature: 0.05,
    smoothing: 1.0,
});

#[test]
fn cem_icem_and_mppi_find_the_plan_worked_by_hand() {
    for optimizer in [CEM, ICEM, MPPI] {
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
        elites: &[],
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

/// Scores from `rollout_model`'s full trace, reduced here by hand: the
/// reference for the trace-free loop behind `score_sequences`.
fn scores_from_trace(
    starts: &[f32],
    sequences: &[f32],
    per_start: usize,
    config: &ScoreConfig,
    seed: u64,
) -> Vec<(f64, f64, f64, Option<usize>)> {
    let tiled: Vec<f32> = starts
        .iter()
        .flat_map(|&s| std::iter::repeat_n(s, per_start))
        .collect();
    let rollout = RolloutConfig {
        horizon: config.horizon,
        particles: config.particles,
        penalty: config.penalty,
        threshold: config.threshold,
        noise_scale: config.noise_scale,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let actions = RolloutActions::Sequence(sequences);
    let trace = rollout_model(&PointMass, actions, &rules(), &tiled, &rollout, &mut rng).trace;
    let p = config.particles;
    (0..tiled.len())
        .map(|c| {
            let (mut ret, mut pen, mut eta) = (0.0, 0.0, 0.0);
            let mut truncated_at = None::<usize>;
            for r in c * p..(c + 1) * p {
                let mut weight = 1.0;
                for t in 0..trace.kept[r] {
                    let reward = f64::from(trace.rewards[r][t]);
                    let e = f64::from(trace.eta[r][t]);
                    ret += weight * reward;
                    pen += weight * (reward - config.penalty * e);
                    eta += e;
                    weight *= config.discount;
                }
                if trace.outcome[r] == StepOutcome::Truncated {
                    let k = trace.kept[r];
                    truncated_at = Some(truncated_at.map_or(k, |t| t.min(k)));
                }
            }
            let n = p as f64;
            (ret / n, pen / n, eta / n, truncated_at)
        })
        .collect()
}

#[test]
fn scores_are_the_model_rollouts_returns_with_noise_and_truncation() {
    let starts = [0.0, 1.0, -0.5];
    let sequences: Vec<f32> = (0..3 * 2 * 4)
        .map(|i| ((i % 5) as f32 - 2.0) * 0.4)
        .collect();
    let config = ScoreConfig {
        horizon: 4,
        particles: 5,
        noise_scale: 0.7,
        ..config(Some(3.0))
    };
    let candidates = Candidates {
        starts: &starts,
        sequences: &sequences,
        per_start: 2,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let scores = score_sequences(
        &PointMass,
        &rules(),
        &candidates,
        &config,
        &mut rng,
        &Cancel::default(),
    )
    .unwrap();
    let reference = scores_from_trace(&starts, &sequences, 2, &config, 9);
    let mut truncations = 0;
    for (s, (ret, pen, eta, truncated_at)) in scores.iter().zip(&reference) {
        assert!(close(s.mean_return, *ret), "{s:?} vs {ret}");
        assert!(close(s.penalized_return, *pen), "{s:?} vs {pen}");
        assert!(close(s.accumulated_eta, *eta), "{s:?} vs {eta}");
        assert_eq!(s.truncated_at, *truncated_at, "{s:?}");
        truncations += usize::from(truncated_at.is_some());
    }
    assert!(truncations > 0, "ε = 3 truncates some particle: {scores:?}");
}

#[test]
fn groups_scored_together_score_as_each_alone() {
    let rules = rules();
    let settings = [
        (vec![0.0, 1.0], 2, config(None), 1),
        (
            vec![0.5],
            3,
            ScoreConfig {
                horizon: 2,
                particles: 4,
                noise_scale: 1.0,
                ..config(Some(1.5))
            },
            2,
        ),
        (
            vec![-1.0, 0.2, 3.0],
            1,
            ScoreConfig {
                noise_scale: 0.3,
                discount: 1.0,
                ..config(None)
            },
            3,
        ),
    ];
    let sequences: Vec<Vec<f32>> = (settings.iter())
        .map(|(starts, per_start, config, _)| {
            (0..starts.len() * per_start * config.horizon)
                .map(|i| (i as f32 * 0.37).sin())
                .collect()
        })
        .collect();
    let candidates = |g: usize| Candidates {
        starts: &settings[g].0,
        sequences: &sequences[g],
        per_start: settings[g].1,
    };
    let cancel = Cancel::default();
    let alone: Vec<Vec<CandidateScore>> = (0..settings.len())
        .map(|g| {
            let mut rng = ChaCha8Rng::seed_from_u64(settings[g].3);
            let c = candidates(g);
            score_sequences(&PointMass, &rules, &c, &settings[g].2, &mut rng, &cancel).unwrap()
        })
        .collect();
    let mut rngs: Vec<ChaCha8Rng> = (settings.iter())
        .map(|s| ChaCha8Rng::seed_from_u64(s.3))
        .collect();
    let cancelled = Cancel::default();
    cancelled.cancel();
    let mut groups: Vec<ScoreGroup> = (rngs.iter_mut().enumerate())
        .map(|(g, rng)| ScoreGroup {
            candidates: candidates(g),
            config: &settings[g].2,
            rng,
            cancel: &cancel,
        })
        .collect();
    // A cancelled caller between them takes nothing from the others.
    let mut spare = ChaCha8Rng::seed_from_u64(0);
    groups.insert(
        1,
        ScoreGroup {
            candidates: candidates(0),
            config: &settings[0].2,
            rng: &mut spare,
            cancel: &cancelled,
        },
    );
    let mut together = score_groups(&PointMass, &rules, groups).into_iter();
    assert_eq!(together.next().unwrap().unwrap(), alone[0]);
    assert!(matches!(
        together.next(),
        Some(Err(PlanningError::Cancelled(_)))
    ));
    assert_eq!(together.next().unwrap().unwrap(), alone[1]);
    assert_eq!(together.next().unwrap().unwrap(), alone[2]);
}

/// iCEM's memory: one iteration of two candidates sampled at a tiny spread
/// around the box's middle (both ≈ [0, 0, 0], return −12) finds nothing,
/// unless the previous call's elite [−1, 1, 1] is among them, shifted to
/// [1, 1, ≈0]: the optimum (return −1), which becomes the plan (momentum 0)
/// and the elite this call leaves for the next.
#[test]
fn icem_tries_the_previous_calls_elites_shifted_one_step() {
    let config = PlanConfig {
        optimizer: Optimizer::Icem(IcemConfig {
            elites: 1,
            momentum: 0.0,
            decay: 1.3,
            colored_noise: 2.0,
            keep_elites: 1.0,
        }),
        population: 2,
        iterations: 1,
        noise: 0.001,
        score: undiscounted_drift(),
    };
    let run = |elites: &[f32]| {
        let start = PlanStart {
            state: &[0.0],
            action_box: &[(-1.0, 1.0)],
            warm: None,
            elites,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        plan(
            &PointMass,
            &reach_rules(),
            &start,
            &config,
            &mut rng,
            &Cancel::default(),
        )
        .unwrap()
    };
    let near =
        |got: &[f32], want: [f32; 3]| got.iter().zip(want).all(|(g, w)| (g - w).abs() < 0.01);
    let cold = run(&[]);
    assert!(near(&cold.actions, [0.0, 0.0, 0.0]), "{cold:?}");
    assert!((cold.objective + 12.0).abs() < 0.1, "{cold:?}");
    let remembered = run(&[-1.0, 1.0, 1.0]);
    assert!(near(&remembered.actions, [1.0, 1.0, 0.0]), "{remembered:?}");
    assert!((remembered.objective + 1.0).abs() < 0.05, "{remembered:?}");
    assert!(near(&remembered.elites, [1.0, 1.0, 0.0]), "{remembered:?}");
}

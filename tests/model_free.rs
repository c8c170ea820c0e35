//! The model-free methods (BC, TD3+BC): each defining mechanism against a
//! hand computation, the state normalisation folded into the saved actor,
//! and a run that checkpoints and resumes bit-exactly.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::{
    ActorConfig, Bc, BcConfig, ConservativeTerm, Cql, CqlConfig, CqlSamples, Edac, EdacConfig,
    LearnerConfig, Method, ModelFreeConfig, ModelFreeTraining, PortableActor, SacConfig, Td3Bc,
    Td3BcConfig, fold_input_normalization,
};
use nuno::artifact::{
    collect_tensors, latest_checkpoint, load_model_free_checkpoint, save_model_free_checkpoint,
};
use nuno::data::{Dataset, GenerateConfig, Stats, generate};
use nuno::envs::{System, TaskConfig, TaskName};
use nuno::infer::Kernel;
use nuno::nn::{seeded_init, to_f32_vec};
use nuno::shared::TransitionBatch;

fn tensor(values: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

fn small_actor(obs_dim: usize, act_dim: usize) -> ActorConfig {
    ActorConfig::new(obs_dim, act_dim, vec![-1.0; act_dim], vec![1.0; act_dim])
        .with_hidden(vec![16, 16])
}

fn td3_config() -> Td3BcConfig {
    Td3BcConfig::new()
        .with_actor_hidden(vec![16, 16])
        .with_critic_hidden(vec![16, 16])
}

fn rows(n: usize, width: usize, phase: f32) -> Vec<f32> {
    (0..n * width)
        .map(|i| (i as f32 * 0.37 + phase).sin())
        .collect()
}

/// BC's loss is the mean over every entry of (π(s) − a)², π(s) = tanh(μ(s))
/// on the unit box.
#[test]
fn bc_loss_is_the_mean_squared_error_of_the_mean_action() {
    let device = Device::flex();
    let bc = seeded_init(&device, 1, || {
        Bc::new(small_actor(4, 3), BcConfig::new(), &device)
    });
    let (obs, actions) = (rows(5, 4, 0.0), rows(5, 3, 1.0));
    let loss = bc
        .loss(
            tensor(obs.clone(), [5, 4], bc.device()),
            tensor(actions.clone(), [5, 3], bc.device()),
        )
        .into_scalar::<f32>();
    let (mean, _) = bc.actor.valid().mean_log_std(tensor(obs, [5, 4], &device));
    let expected = to_f32_vec(mean)
        .iter()
        .zip(&actions)
        .map(|(&mu, &a)| (f64::from(mu).tanh() - f64::from(a)).powi(2))
        .sum::<f64>()
        / 15.0;
    assert!(
        (f64::from(loss) - expected).abs() < 1e-6,
        "{loss} vs {expected}"
    );
}

/// BC learns a mapping the data shows: after some steps on a = 0.5·sign(s₀),
/// its actions follow the sign.
#[test]
fn bc_clones_the_dataset_actions() {
    let device = Device::flex();
    let mut bc = seeded_init(&device, 2, || {
        Bc::new(small_actor(2, 1), BcConfig::new().with_lr(1e-2), &device)
    });
    let obs = rows(64, 2, 0.3);
    let actions: Vec<f32> = obs.chunks(2).map(|s| 0.5 * s[0].signum()).collect();
    let batch = TransitionBatch {
        observations: obs.clone(),
        actions: actions.clone(),
        rewards: vec![0.0; 64],
        next_observations: obs.clone(),
        terminals: vec![0.0; 64],
    };
    let first = bc.update(&batch).actor_loss;
    let mut last = first;
    for _ in 0..300 {
        last = bc.update(&batch).actor_loss;
    }
    assert!(last < 0.1 * first, "loss {first} → {last}");
    let acted = to_f32_vec(bc.actor.valid().mean_action(tensor(obs, [64, 2], &device)));
    let agree = acted
        .iter()
        .zip(&actions)
        .filter(|(p, a)| p.signum() == a.signum())
        .count();
    assert!(agree >= 60, "{agree} of 64 signs agree");
}

/// The critics' last layer scaled by c leaves the actor loss unchanged: the Q
/// term is normalised by λ = α / mean|Q₁| (TD3+BC's defining mechanism); without
/// it, the loss's Q term would scale by c.
#[test]
fn td3_bc_actor_loss_is_invariant_to_the_critic_scale() {
    let device = Device::flex();
    let td3 = seeded_init(&device, 3, || {
        Td3Bc::new(small_actor(4, 2), td3_config(), &device)
    });
    let (obs, actions) = (rows(8, 4, 0.0), rows(8, 2, 2.0));
    let loss_of = |agent: &Td3Bc| {
        let (loss, lambda) = agent.actor_loss(
            tensor(obs.clone(), [8, 4], agent.device()),
            tensor(actions.clone(), [8, 2], agent.device()),
        );
        (f64::from(loss.into_scalar::<f32>()), f64::from(lambda))
    };
    let (loss, lambda) = loss_of(&td3);

    // λ and the loss by hand, from the networks' outputs.
    let actor = td3.actor.valid();
    let pi = actor.mean_action(tensor(obs.clone(), [8, 4], &device));
    let input = Tensor::cat(vec![tensor(obs.clone(), [8, 4], &device), pi.clone()], 1);
    let q1 = to_f32_vec(td3.critic.valid().q1.forward(input));
    let mean_abs = q1.iter().map(|q| f64::from(q.abs())).sum::<f64>() / 8.0;
    assert!((lambda - 2.5 / mean_abs).abs() < 1e-4 * lambda, "{lambda}");
    let mean_q = q1.iter().map(|&q| f64::from(q)).sum::<f64>() / 8.0;
    let bc = to_f32_vec(pi)
        .iter()
        .zip(&actions)
        .map(|(&p, &a)| (f64::from(p) - f64::from(a)).powi(2))
        .sum::<f64>()
        / 16.0;
    let expected = -2.5 * mean_q / mean_abs + bc;
    assert!((loss - expected).abs() < 1e-4, "{loss} vs {expected}");

    let mut scaled = td3;
    let last = scaled.critic.q1.layers.len() - 1;
    let layer = &mut scaled.critic.q1.layers[last];
    layer.weight = Param::initialized(layer.weight.id, layer.weight.val() * 10.0);
    let bias = layer.bias.take().unwrap();
    layer.bias = Some(Param::initialized(bias.id, bias.val() * 10.0));
    let (scaled_loss, scaled_lambda) = loss_of(&scaled);
    assert!((scaled_lambda - lambda / 10.0).abs() < 1e-4 * lambda);
    assert!((scaled_loss - loss).abs() < 1e-4, "{scaled_loss} vs {loss}");
}

/// The critic target's smoothing noise is clipped to ±c half-widths and the
/// action to the box: with huge noise, the target critics are read at
/// clip(π̄(s') ± 0.5, ±1).
#[test]
fn td3_bc_target_clips_the_smoothing_noise_and_the_action() {
    let device = Device::flex();
    let td3 = seeded_init(&device, 4, || {
        Td3Bc::new(small_actor(3, 2), td3_config(), &device)
    });
    let next_obs = rows(4, 3, 0.5);
    let noise: Vec<f32> = (0..8)
        .map(|i| if i % 2 == 0 { 100.0 } else { -100.0 })
        .collect();
    let (rewards, terminals) = (vec![1.0, 0.5, -1.0, 2.0], vec![0.0, 1.0, 0.0, 0.0]);
    let y = to_f32_vec(td3.critic_target(
        tensor(next_obs.clone(), [4, 3], &device),
        tensor(rewards.clone(), [4, 1], &device),
        tensor(terminals.clone(), [4, 1], &device),
        tensor(noise.clone(), [4, 2], &device),
    ));
    let pi = to_f32_vec(
        td3.target_actor
            .mean_action(tensor(next_obs.clone(), [4, 3], &device)),
    );
    let action: Vec<f32> = (pi.iter().zip(&noise))
        .map(|(&p, &e)| (p + 0.5 * e.signum()).clamp(-1.0, 1.0))
        .collect();
    let min_q = to_f32_vec(td3.target_critic.min_q(
        tensor(next_obs, [4, 3], &device),
        tensor(action, [4, 2], &device),
    ));
    for row in 0..4 {
        let expected = rewards[row] + 0.99 * (1.0 - terminals[row]) * min_q[row];
        assert!(
            (y[row] - expected).abs() < 1e-5,
            "row {row}: {} vs {expected}",
            y[row]
        );
    }
}

/// The saved actor on raw states acts as the trained one on normalised states.
#[test]
fn the_folded_normalisation_acts_as_normalising_first() {
    let device = Device::flex();
    let actor = seeded_init(&device, 5, || small_actor(3, 2).init(&device));
    let stats = Stats {
        mean: vec![1.0, -2.0, 0.5],
        std: vec![0.5, 3.0, 1.5],
    };
    let raw = rows(6, 3, 0.2);
    let mut normalised = raw.clone();
    stats.normalize(&mut normalised);
    let expected = to_f32_vec(actor.mean_action(tensor(normalised, [6, 3], &device)));
    let folded = fold_input_normalization(actor, &stats);
    let got = to_f32_vec(folded.mean_action(tensor(raw, [6, 3], &device)));
    for (g, e) in got.iter().zip(&expected) {
        assert!((g - e).abs() < 1e-5, "{g} vs {e}");
    }
}

fn cql_config(weight: f64) -> CqlConfig {
    let sac = SacConfig::new()
        .with_actor_hidden(vec![16, 16])
        .with_critic_hidden(vec![16, 16]);
    let term = ConservativeTerm::new()
        .with_cql_weight(weight)
        .with_num_repeat_actions(3);
    CqlConfig::new().with_sac(sac).with_term(term)
}

/// CQL's conservative term by hand: each of the B·N repeated rows takes the
/// log-sum-exp over its three sources (π at s, π at s' read by Q at s, the
/// uniform action less log 0.5^|A|), then the mean, less mean Q(s, a), × β.
#[test]
fn cql_conservative_term_is_the_reference_log_sum_exp() {
    let device = Device::flex();
    let cql = seeded_init(&device, 6, || {
        Cql::new(small_actor(3, 2), cql_config(5.0), &device)
    });
    let plain = Device::flex();
    let (obs, next_obs, actions) = (rows(2, 3, 0.0), rows(2, 3, 1.0), rows(2, 2, 2.0));
    let (noise_s, noise_next) = (rows(6, 2, 3.0), rows(6, 2, 4.0));
    let uniform: Vec<f32> = rows(6, 2, 5.0).iter().map(|x| x * 0.9).collect();
    let samples = CqlSamples {
        noise_at_state: tensor(noise_s.clone(), [6, 2], cql.device()),
        noise_at_next: tensor(noise_next.clone(), [6, 2], cql.device()),
        uniform: tensor(uniform.clone(), [6, 2], cql.device()),
    };
    let (term1, _) = cql.conservative_terms(
        tensor(obs.clone(), [2, 3], cql.device()),
        tensor(next_obs.clone(), [2, 3], cql.device()),
        tensor(actions.clone(), [2, 2], cql.device()),
        samples,
    );
    let term1 = f64::from(term1.into_scalar::<f32>());

    let actor = cql.sac.actor.valid();
    let critic = cql.sac.critic.valid();
    // Row r of the repeated batch is state r / 3.
    let repeat = |x: &[f32], w: usize| -> Vec<f32> {
        (0..6)
            .flat_map(|r| x[(r / 3) * w..(r / 3 + 1) * w].to_vec())
            .collect()
    };
    let (obs_n, next_n) = (repeat(&obs, 3), repeat(&next_obs, 3));
    let at_s = actor.sample(
        tensor(obs_n.clone(), [6, 3], &plain),
        tensor(noise_s, [6, 2], &plain),
    );
    let at_next = actor.sample(
        tensor(next_n, [6, 3], &plain),
        tensor(noise_next, [6, 2], &plain),
    );
    let q1 = |o: &[f32], a: Tensor<2>, n: usize| -> Vec<f64> {
        let (q, _) = critic.forward(tensor(o.to_vec(), [n, 3], &plain), a);
        to_f32_vec(q).into_iter().map(f64::from).collect()
    };
    let (pi, next) = (q1(&obs_n, at_s.action, 6), q1(&obs_n, at_next.action, 6));
    let random = q1(&obs_n, tensor(uniform, [6, 2], &plain), 6);
    let (log_pi, log_next) = (to_f32_vec(at_s.log_prob), to_f32_vec(at_next.log_prob));
    let uniform_log_density = 2.0 * 0.5f64.ln();
    let lse: f64 = (0..6)
        .map(|r| {
            let x = [
                pi[r] - f64::from(log_pi[r]),
                next[r] - f64::from(log_next[r]),
                random[r] - uniform_log_density,
            ];
            x.iter().map(|v| v.exp()).sum::<f64>().ln()
        })
        .sum::<f64>()
        / 6.0;
    let data = q1(&obs, tensor(actions, [2, 2], &plain), 2);
    let expected = 5.0 * (lse - (data[0] + data[1]) / 2.0);
    assert!((term1 - expected).abs() < 1e-4, "{term1} vs {expected}");
}

/// COMBO's split: the data term reads the batch's first (real) rows only,
/// the log-sum-exp every row, so moving the split by k rows changes the term
/// by β·(mean Q over all rows − mean Q over the first k) exactly.
#[test]
fn combo_data_term_reads_the_real_rows_only() {
    let device = Device::flex();
    let cql = seeded_init(&device, 7, || {
        Cql::new(small_actor(3, 2), cql_config(5.0), &device)
    });
    let (obs, next_obs, actions) = (rows(4, 3, 0.0), rows(4, 3, 1.0), rows(4, 2, 2.0));
    let samples = || CqlSamples {
        noise_at_state: tensor(rows(12, 2, 3.0), [12, 2], cql.device()),
        noise_at_next: tensor(rows(12, 2, 4.0), [12, 2], cql.device()),
        uniform: tensor(rows(12, 2, 5.0), [12, 2], cql.device()),
    };
    let term = |data_rows: usize| -> f64 {
        let (t1, _) = cql.config.term.terms(
            &cql.sac,
            tensor(obs.clone(), [4, 3], cql.device()),
            tensor(next_obs.clone(), [4, 3], cql.device()),
            tensor(actions.clone(), [4, 2], cql.device()),
            samples(),
            data_rows,
        );
        f64::from(t1.into_scalar::<f32>())
    };
    let (q1, _) = cql.sac.critic.valid().forward(
        tensor(obs.clone(), [4, 3], &device),
        tensor(actions.clone(), [4, 2], &device),
    );
    let q: Vec<f64> = to_f32_vec(q1).into_iter().map(f64::from).collect();
    let mean = |k: usize| q[..k].iter().sum::<f64>() / k as f64;
    let expected = 5.0 * (mean(4) - mean(1));
    let got = term(1) - term(4);
    assert!((got - expected).abs() < 1e-4, "{got} vs {expected}");
    assert!(
        expected.abs() > 1e-3,
        "the split must matter here: {expected}"
    );
}

/// The term does its job: trained on one batch, CQL's critics value uniform
/// actions below the dataset's actions by far more than SAC's with β = 0.
#[test]
fn cql_pushes_down_the_values_of_unseen_actions() {
    let device = Device::flex();
    let obs = rows(32, 3, 0.7);
    let actions: Vec<f32> = rows(32, 2, 1.3).iter().map(|a| 0.3 * a).collect();
    let batch = TransitionBatch {
        observations: obs.clone(),
        actions: actions.clone(),
        rewards: rows(32, 1, 2.0),
        next_observations: rows(32, 3, 0.9),
        terminals: vec![0.0; 32],
    };
    let uniform: Vec<f32> = rows(32, 2, 6.0);
    let gap = |weight: f64| -> f64 {
        // A critic lr of 3e-3 (10× the reference's) so that 150 updates move the values.
        let mut config = cql_config(weight);
        config.sac.critic_lr = 3e-3;
        let mut cql = seeded_init(&device, 8, || Cql::new(small_actor(3, 2), config, &device));
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
        for _ in 0..150 {
            cql.update(&batch, &mut rng);
        }
        let critic = cql.sac.critic.valid();
        let mean_q = |a: &[f32]| -> f64 {
            let (q, _) = critic.forward(
                tensor(obs.clone(), [32, 3], &device),
                tensor(a.to_vec(), [32, 2], &device),
            );
            to_f32_vec(q).iter().map(|&v| f64::from(v)).sum::<f64>() / 32.0
        };
        mean_q(&actions) - mean_q(&uniform)
    };
    let (conservative, plain) = (gap(5.0), gap(0.0));
    assert!(
        conservative > plain + 1.0,
        "Q(data) − Q(uniform): {conservative:.3} with β = 5, {plain:.3} with β = 0"
    );
}

fn edac(critics: usize) -> Edac {
    let device = Device::flex();
    let sac = SacConfig::new()
        .with_actor_hidden(vec![8, 8])
        .with_critic_hidden(vec![8, 8]);
    let config = EdacConfig::new().with_sac(sac).with_num_critics(critics);
    seeded_init(&device, 12, || {
        Edac::new(small_actor(3, 2), config, &device)
    })
}

/// EDAC's diversity term against finite differences: each critic's action
/// gradient by central differences, normalised, the pairwise products over
/// i ≠ j summed per row, the mean over rows over N − 1.
#[test]
fn edac_diversity_term_matches_finite_differences() {
    let agent = edac(4);
    let device = Device::flex();
    let (obs, actions) = (rows(5, 3, 0.1), rows(5, 2, 0.8));
    let got = agent
        .diversity_loss(
            tensor(obs.clone(), [5, 3], agent.device()),
            tensor(actions.clone(), [5, 2], agent.device()),
        )
        .into_scalar::<f32>();
    let critics = agent.critics.valid();
    let q = |j: usize, a: &[f32]| -> Vec<f64> {
        let qs = critics.forward(
            tensor(obs.clone(), [5, 3], &device),
            tensor(a.to_vec(), [5, 2], &device),
        );
        to_f32_vec(qs[j].clone())
            .into_iter()
            .map(f64::from)
            .collect()
    };
    let h = 1e-3f32;
    // gradients[j][row][k]
    let gradients: Vec<Vec<[f64; 2]>> = (0..4)
        .map(|j| {
            let mut g = vec![[0.0; 2]; 5];
            for k in 0..2 {
                let shifted = |sign: f32| -> Vec<f32> {
                    (actions.iter().enumerate())
                        .map(|(i, &a)| if i % 2 == k { a + sign * h } else { a })
                        .collect()
                };
                let (up, down) = (q(j, &shifted(1.0)), q(j, &shifted(-1.0)));
                for (row, (u, d)) in g.iter_mut().zip(up.iter().zip(&down)) {
                    row[k] = (u - d) / (2.0 * f64::from(h));
                }
            }
            for row in &mut g {
                let norm = (row[0] * row[0] + row[1] * row[1]).sqrt() + 1e-10;
                *row = [row[0] / norm, row[1] / norm];
            }
            g
        })
        .collect();
    let mut total = 0.0;
    for (i, gi) in gradients.iter().enumerate() {
        for (j, gj) in gradients.iter().enumerate() {
            if i != j {
                total += (gi.iter().zip(gj))
                    .map(|(a, b)| a[0] * b[0] + a[1] * b[1])
                    .sum::<f64>();
            }
        }
    }
    let expected = total / 5.0 / 3.0;
    assert!(
        (f64::from(got) - expected).abs() < 2e-3,
        "{got} vs {expected}"
    );
}

/// EDAC's critics start as the reference's: every bias 0.1 but the last
/// layer's, whose weights and bias lie within ±3e-3.
#[test]
fn edac_critics_start_as_the_reference() {
    let agent = edac(3);
    for member in &agent.critics.valid().members {
        let last = member.layers.len() - 1;
        for (i, layer) in member.layers.iter().enumerate() {
            let bias = to_f32_vec(layer.bias.as_ref().unwrap().val().unsqueeze::<2>());
            if i < last {
                assert!(bias.iter().all(|&b| b == 0.1), "{bias:?}");
            } else {
                let weight = to_f32_vec(layer.weight.val());
                assert!(
                    weight.iter().chain(&bias).all(|w| w.abs() <= 3e-3),
                    "{weight:?}"
                );
                assert!(weight.iter().any(|&w| w != 0.0));
            }
        }
    }
}

fn small_dataset() -> Dataset {
    let policy = PortableActor::rlkit_random(11, 3, &[64, 64], 4);
    let config = GenerateConfig::new(TaskConfig::d4rl(TaskName::Hopper), "random", 2000, 4);
    generate(&config, &policy, "test", &|_| {}).unwrap()
}

fn tiny_config(method: Method) -> ModelFreeConfig {
    let mut learner = LearnerConfig::for_method(method).unwrap();
    learner.set_hidden(&[16, 16]);
    learner.set_batch_size(32);
    ModelFreeConfig {
        learner,
        steps_per_epoch: 15,
        epochs: 2,
        eval_episodes: 1,
        seed: 9,
    }
}

/// Two epochs straight, or one, a checkpoint, a fresh state and the second:
/// the same networks, optimiser moments and history (policy delay included,
/// on an odd number of updates per epoch).
#[test]
fn td3_bc_runs_checkpoints_and_resumes_bit_exactly() {
    let dataset = small_dataset();
    let system = System::Task(TaskConfig::d4rl(TaskName::Hopper));
    let device = Device::flex();
    let fresh =
        || ModelFreeTraining::new(tiny_config(Method::Td3Bc), &dataset, &system, &device).unwrap();
    let mut straight = fresh();
    let initial = tempfile::tempdir().unwrap();
    save_model_free_checkpoint(initial.path(), &straight).unwrap();
    for _ in 0..2 {
        straight.run_epoch(&dataset, Kernel::Burn).unwrap();
    }
    let last = straight.history.last().unwrap();
    assert!(last.losses.qf1_loss.is_finite() && last.eval.mean_return.is_finite());

    let mut first = fresh();
    let start = latest_checkpoint(initial.path()).unwrap().unwrap();
    load_model_free_checkpoint(&start, &mut first).unwrap();
    first.run_epoch(&dataset, Kernel::Burn).unwrap();
    let dir = tempfile::tempdir().unwrap();
    save_model_free_checkpoint(dir.path(), &first).unwrap();
    drop(first);
    let mut resumed = fresh();
    let checkpoint = latest_checkpoint(dir.path()).unwrap().unwrap();
    load_model_free_checkpoint(&checkpoint, &mut resumed).unwrap();
    assert_eq!((resumed.epoch, resumed.step), (1, 15));
    resumed.run_epoch(&dataset, Kernel::Burn).unwrap();

    assert_eq!(
        collect_tensors(&resumed.actor()),
        collect_tensors(&straight.actor())
    );
    let (nuno::agent::Learner::Td3Bc(a), nuno::agent::Learner::Td3Bc(b)) =
        (&resumed.learner, &straight.learner)
    else {
        panic!("TD3+BC learners");
    };
    assert_eq!(
        collect_tensors(&a.target_critic),
        collect_tensors(&b.target_critic)
    );
    assert_eq!(a.adam, b.adam);
    let strip = |h: &[nuno::agent::EpochRecord]| -> Vec<String> {
        h.iter()
            .map(|r| format!("{:?} {:?}", r.losses, r.eval))
            .collect()
    };
    assert_eq!(strip(&resumed.history), strip(&straight.history));

    // A checkpoint of another method is refused by name.
    let mut bc =
        ModelFreeTraining::new(tiny_config(Method::Bc), &dataset, &system, &device).unwrap();
    let err = load_model_free_checkpoint(&checkpoint, &mut bc)
        .unwrap_err()
        .to_string();
    assert!(err.contains("different configuration"), "{err}");
}

//! The fused CPU SAC update against burn's autodiff, the reference: every
//! gradient, one whole update, a thousand updates on a fixed stream, and
//! checkpoints that either kernel resumes.

use std::collections::BTreeMap;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::{
    ActorConfig, ConservativeTerm, CriticBackup, Edac, EdacConfig, FusedSac, Sac, SacAdam,
    SacConfig, SacLosses, actor_loss, alpha_loss,
};
use nuno::artifact::{NamedTensors, collect_tensors};
use nuno::infer::TrainableMlp;
use nuno::nn::{gradients_by_path, normal, seeded_init};
use nuno::shared::TransitionBatch;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OBS: usize = 11;
const ACT: usize = 3;

/// SAC with 64-wide networks (the default 256 checks the same code, slower).
fn agent(seed: u64) -> Sac {
    let device = Device::flex();
    let actor = ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT]);
    let config = SacConfig::new()
        .with_actor_hidden(vec![64, 64])
        .with_critic_hidden(vec![64, 64])
        .with_initial_alpha(0.7);
    seeded_init(&device, seed, || Sac::new(actor, config, &device))
}

/// Random transitions (a fixed stream when `rng` is).
fn batch(rows: usize, rng: &mut ChaCha8Rng) -> TransitionBatch {
    let mut uniform = |n: usize, scale: f32| -> Vec<f32> {
        (0..n).map(|_| rng.random_range(-scale..scale)).collect()
    };
    TransitionBatch {
        observations: uniform(rows * OBS, 2.0),
        actions: uniform(rows * ACT, 1.0),
        rewards: uniform(rows, 3.0),
        next_observations: uniform(rows * OBS, 2.0),
        terminals: (0..rows).map(|i| f32::from(i % 7 == 0)).collect(),
    }
}

fn fused_named(prefix: &str, net: &TrainableMlp) -> BTreeMap<String, Vec<f32>> {
    net.layers
        .iter()
        .enumerate()
        .flat_map(|(i, l)| {
            [
                (format!("{prefix}layers.{i}.weight"), l.weight.clone()),
                (format!("{prefix}layers.{i}.bias"), l.bias.clone()),
            ]
        })
        .collect()
}

/// Every value within 1e-5 relative or 1e-6 absolute.
fn assert_close(what: &str, ours: &[f32], reference: &[f32], relative: f32, absolute: f32) {
    assert_eq!(ours.len(), reference.len(), "{what}: sizes");
    for (i, (a, b)) in ours.iter().zip(reference).enumerate() {
        let tolerance = absolute.max(relative * b.abs());
        assert!(
            (a - b).abs() <= tolerance,
            "{what}[{i}]: fused {a} vs burn {b}"
        );
    }
}

#[test]
fn every_gradient_matches_burn_autodiff() {
    let sac = agent(1);
    let mut fused = FusedSac::from_sac(&sac);
    let data = batch(256, &mut ChaCha8Rng::seed_from_u64(2));
    let ours = fused.gradients(&data, &mut ChaCha8Rng::seed_from_u64(3));

    // burn, on the same weights, batch and ε (drawn in the same order).
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let device = sac.device().clone();
    let plain = device.clone().inner();
    let b = data.rewards.len();
    let rows = |values: &[f32], width: usize, device: &Device| {
        Tensor::<2>::from_data(TensorData::new(values.to_vec(), [b, width]), device)
    };
    let y = sac.critic_target(
        rows(&data.next_observations, OBS, &plain),
        rows(&data.rewards, 1, &plain),
        rows(&data.terminals, 1, &plain),
        normal([b, ACT], &mut rng, &plain),
    );
    let obs = rows(&data.observations, OBS, &device);
    let (critic_loss, ..) = sac.critic_loss(obs.clone(), rows(&data.actions, ACT, &device), y);
    let critic = gradients_by_path(
        &sac.critic,
        &GradientsParams::from_grads(critic_loss.backward(), &sac.critic),
    );
    let alpha = sac.temperature.alpha().inner();
    let noise = normal([b, ACT], &mut rng, &device);
    let (actor_loss, log_prob) =
        actor_loss(&sac.actor, obs, noise, alpha, |o, a| sac.critic.min_q(o, a));
    let actor = gradients_by_path(
        &sac.actor,
        &GradientsParams::from_grads(actor_loss.backward(), &sac.actor),
    );
    let alpha_loss = alpha_loss(&sac.temperature, log_prob.inner(), sac.target_entropy);
    let temperature = gradients_by_path(
        &sac.temperature,
        &GradientsParams::from_grads(alpha_loss.backward(), &sac.temperature),
    );

    let mut fused_critic = fused_named("q1.", &ours.critics[0]);
    fused_critic.extend(fused_named("q2.", &ours.critics[1]));
    let fused_actor = fused_named("net.", &ours.actor);
    assert_eq!(
        critic.keys().collect::<Vec<_>>(),
        fused_critic.keys().collect::<Vec<_>>()
    );
    assert_eq!(
        actor.keys().collect::<Vec<_>>(),
        fused_actor.keys().collect::<Vec<_>>()
    );
    for (name, reference) in critic.iter().chain(&actor) {
        let ours = fused_critic.get(name).or(fused_actor.get(name)).unwrap();
        assert_close(name, ours, reference, 1e-5, 1e-6);
    }
    assert_close(
        "log_alpha",
        &[ours.log_alpha],
        &temperature["log_alpha"],
        1e-5,
        1e-6,
    );
}

fn all_tensors(sac: &Sac) -> BTreeMap<String, Vec<f32>> {
    by_module([
        ("actor", collect_tensors(&sac.actor)),
        ("critic", collect_tensors(&sac.critic)),
        ("target_critic", collect_tensors(&sac.target_critic)),
        ("temperature", collect_tensors(&sac.temperature)),
    ])
}

/// Every tensor of the modules, named `module.path`.
fn by_module<const N: usize>(modules: [(&str, NamedTensors); N]) -> BTreeMap<String, Vec<f32>> {
    let mut out = BTreeMap::new();
    for (prefix, tensors) in modules {
        for (name, (_, values)) in tensors {
            out.insert(format!("{prefix}.{name}"), values);
        }
    }
    out
}

/// An update's reported losses, in one order.
fn loss_fields(l: &SacLosses) -> [f32; 7] {
    [
        l.qf1_values,
        l.qf1_loss,
        l.qf2_loss,
        l.actor_loss,
        l.alpha,
        l.alpha_loss,
        l.entropy,
    ]
}

#[test]
fn one_update_equals_burns_update() {
    let mut reference = agent(4);
    let mut fused = FusedSac::from_sac(&reference);
    let data = batch(256, &mut ChaCha8Rng::seed_from_u64(5));
    let burn_losses = reference.update(&data, &mut ChaCha8Rng::seed_from_u64(6));
    let fused_losses = fused.update(&data, &mut ChaCha8Rng::seed_from_u64(6));
    // Another agent takes everything the fused kernel holds.
    let mut ours = agent(7);
    fused.write_to(&mut ours);

    let (expected, got) = (all_tensors(&reference), all_tensors(&ours));
    for (name, values) in &expected {
        assert_close(name, &got[name], values, 1e-5, 1e-6);
    }
    for (name, (r, o)) in [
        ("actor", (&reference.adam.actor, &ours.adam.actor)),
        ("critic", (&reference.adam.critic, &ours.adam.critic)),
        ("alpha", (&reference.adam.alpha, &ours.adam.alpha)),
    ] {
        assert_eq!(r.time, 1);
        assert_eq!(o.time, 1);
        assert_eq!(
            r.moments.keys().collect::<Vec<_>>(),
            o.moments.keys().collect::<Vec<_>>()
        );
        for (path, m) in &r.moments {
            let what = format!("{name}/{path}");
            assert_close(&what, &o.moments[path].first, &m.first, 1e-5, 1e-9);
            assert_close(&what, &o.moments[path].second, &m.second, 1e-5, 1e-12);
        }
    }
    assert_close(
        "losses",
        &loss_fields(&fused_losses),
        &loss_fields(&burn_losses),
        1e-5,
        1e-6,
    );
}

/// One loss of [`SacLosses`].
type Field = fn(&SacLosses) -> f32;

#[test]
fn a_thousand_updates_track_burns_losses() {
    let mut reference = agent(8);
    let mut fused = FusedSac::from_sac(&reference);
    let (mut burn_rng, mut fused_rng) =
        (ChaCha8Rng::seed_from_u64(9), ChaCha8Rng::seed_from_u64(9));
    let mut data = ChaCha8Rng::seed_from_u64(10);
    let (mut burn_losses, mut fused_losses) = (Vec::new(), Vec::new());
    for _ in 0..1000 {
        let stream = batch(64, &mut data);
        burn_losses.push(reference.update(&stream, &mut burn_rng));
        fused_losses.push(fused.update(&stream, &mut fused_rng));
    }
    // Means over windows of 100 updates, per loss.
    let windows = |losses: &[SacLosses], field: Field| -> Vec<f32> {
        losses
            .chunks(100)
            .map(|w| w.iter().map(field).sum::<f32>() / w.len() as f32)
            .collect()
    };
    let fields: [(&str, Field); 5] = [
        ("qf1_loss", |l| l.qf1_loss),
        ("qf2_loss", |l| l.qf2_loss),
        ("actor_loss", |l| l.actor_loss),
        ("alpha", |l| l.alpha),
        ("entropy", |l| l.entropy),
    ];
    for (name, field) in fields {
        let (b, f) = (windows(&burn_losses, field), windows(&fused_losses, field));
        // Measured: within 2e-5 relative after 1000 updates (64-wide networks);
        // rounding differences grow slowly through the updates.
        assert_close(name, &f, &b, 1e-4, 1e-5);
    }
}

/// MOBILE's critic target: the deterministic backup leaves out exactly
/// −γ(1 − d)·α·log π(ã'|s') (the same ã', computed apart), the floor lifts
/// every target below it to it, and the fused kernel's update with both
/// equals burn's; both kernels' target values min_j Q̄_j(s, ã) agree.
#[test]
fn mobiles_backup_and_target_values_match_a_hand_computation_on_both_kernels() {
    let rows = 64;
    let data = batch(rows, &mut ChaCha8Rng::seed_from_u64(20));
    let stochastic = agent(21);
    let mut deterministic = agent(21);
    deterministic.config.backup = Some(CriticBackup {
        deterministic: true,
        floor: None,
    });
    let plain = Device::flex().inner();
    let column = |v: &[f32]| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [rows, 1]), &plain);
    let next_obs = Tensor::<2>::from_data(
        TensorData::new(data.next_observations.clone(), [rows, OBS]),
        &plain,
    );
    let noise = normal([rows, ACT], &mut ChaCha8Rng::seed_from_u64(22), &plain);
    let target = |sac: &Sac| {
        let y = sac.critic_target(
            next_obs.clone(),
            column(&data.rewards),
            column(&data.terminals),
            noise.clone(),
        );
        nuno::nn::to_f32_vec(y)
    };
    let (with_entropy, without) = (target(&stochastic), target(&deterministic));
    let log_prob = nuno::nn::to_f32_vec(
        stochastic
            .actor
            .valid()
            .sample(next_obs.clone(), noise.clone())
            .log_prob,
    );
    let alpha = 0.7f32;
    let expected: Vec<f32> = (0..rows)
        .map(|r| with_entropy[r] + 0.99 * (1.0 - data.terminals[r]) * alpha * log_prob[r])
        .collect();
    assert_close("deterministic backup", &without, &expected, 1e-5, 1e-5);

    let mut floored = agent(21);
    floored.config.backup = Some(CriticBackup {
        deterministic: true,
        floor: Some(0.0),
    });
    let lifted = target(&floored);
    assert!(
        without.iter().any(|&y| y < 0.0),
        "the data must reach below the floor"
    );
    for (y, raw) in lifted.iter().zip(&without) {
        assert_eq!(*y, raw.max(0.0));
    }

    // One whole update with both settings, fused against burn.
    let mut reference = floored;
    let mut fused = FusedSac::from_sac(&reference);
    reference.update(&data, &mut ChaCha8Rng::seed_from_u64(23));
    fused.update(&data, &mut ChaCha8Rng::seed_from_u64(23));
    let mut ours = agent(24);
    fused.write_to(&mut ours);
    let (expected, got) = (all_tensors(&reference), all_tensors(&ours));
    for (name, values) in &expected {
        assert_close(name, &got[name], values, 1e-5, 1e-6);
    }

    let values = reference.target_values(&data.observations, &mut ChaCha8Rng::seed_from_u64(25));
    let fused_values = FusedSac::from_sac(&reference)
        .target_values(&data.observations, &mut ChaCha8Rng::seed_from_u64(25));
    assert_close("target values", &fused_values, &values, 1e-5, 1e-5);
}

/// A CQL-shaped agent (three hidden layers, 32 wide to stay quick).
fn cql_agent(seed: u64) -> Sac {
    let device = Device::flex();
    let actor = ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT]);
    let config = SacConfig::new()
        .with_actor_hidden(vec![32, 32, 32])
        .with_critic_hidden(vec![32, 32, 32])
        .with_initial_alpha(0.7);
    seeded_init(&device, seed, || Sac::new(actor, config, &device))
}

/// CQL's and COMBO's update (actor, α, critics with the conservative term,
/// targets) on the fused kernel equals burn's autodiff of the same losses: on
/// a batch all real (CQL) and on one whose second half is model rows (COMBO's
/// data term on the first half), with a temperature other than 1.
#[test]
fn the_conservative_update_equals_burns() {
    let term = ConservativeTerm::new()
        .with_cql_weight(5.0)
        .with_temperature(2.0)
        .with_num_repeat_actions(4);
    let rows = 64;
    let data = batch(rows, &mut ChaCha8Rng::seed_from_u64(30));
    for (case, data_rows) in [("CQL", rows), ("COMBO", rows / 2)] {
        let mut reference = cql_agent(31);
        let mut fused = FusedSac::from_sac(&reference);
        let rng = || ChaCha8Rng::seed_from_u64(32);
        let burn_losses = term.update(&mut reference, &data, data_rows, &mut rng());
        let fused_losses = fused.update_conservative(&term, &data, data_rows, &mut rng());
        let mut ours = cql_agent(33);
        fused.write_to(&mut ours);
        let (expected, got) = (all_tensors(&reference), all_tensors(&ours));
        for (name, values) in &expected {
            assert_close(&format!("{case} {name}"), &got[name], values, 1e-5, 1e-6);
        }
        let (f, b) = (loss_fields(&fused_losses), loss_fields(&burn_losses));
        assert_close(case, &f, &b, 1e-5, 1e-6);
    }
}

/// EDAC's update (actor, α read clamped, then the N critics with the
/// ensemble-gradient diversity term, then the targets) on the fused kernel
/// equals burn's autodiff of the same losses, with and without the term.
#[test]
fn edacs_update_equals_burns() {
    let device = Device::flex();
    let actor = ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT]);
    let sac = SacConfig::new()
        .with_actor_hidden(vec![32, 32, 32])
        .with_critic_hidden(vec![32, 32, 32])
        .with_initial_alpha(0.7);
    let data = batch(64, &mut ChaCha8Rng::seed_from_u64(40));
    for eta in [0.0, 3.0] {
        let config = EdacConfig::new()
            .with_sac(sac.clone())
            .with_num_critics(5)
            .with_eta(eta);
        let edac = || {
            seeded_init(&device, 41, || {
                Edac::new(actor.clone(), config.clone(), &device)
            })
        };
        let mut reference = edac();
        let mut fused = FusedSac::from_edac(&reference);
        let rng = || ChaCha8Rng::seed_from_u64(42);
        let burn_losses = reference.update(&data, &mut rng());
        let fused_losses = fused.update_edac(eta as f32, &data, &mut rng());
        let mut ours = seeded_init(&device, 43, || {
            Edac::new(actor.clone(), config.clone(), &device)
        });
        fused.write_to_edac(&mut ours);
        let tensors = |e: &Edac| {
            by_module([
                ("actor", collect_tensors(&e.actor)),
                ("critics", collect_tensors(&e.critics)),
                ("target_critics", collect_tensors(&e.target_critics)),
                ("temperature", collect_tensors(&e.temperature)),
            ])
        };
        let (expected, got) = (tensors(&reference), tensors(&ours));
        for (name, values) in &expected {
            assert_close(&format!("η {eta}: {name}"), &got[name], values, 1e-5, 1e-6);
        }
        let keys = |a: &SacAdam| a.critic.moments.keys().cloned().collect::<Vec<_>>();
        assert_eq!(keys(&ours.adam), keys(&reference.adam));
        let (f, b) = (loss_fields(&fused_losses), loss_fields(&burn_losses));
        assert_close(&format!("η {eta}"), &f, &b, 1e-5, 1e-6);
    }
}

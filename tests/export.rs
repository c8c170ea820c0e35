//! ONNX export (issue 36, item 4): the exported SDE step and policy, run by
//! ONNX Runtime from PyPI (`tests/python/onnx_export.py`), answer what the
//! server's own code answers on the same inputs and noise — the fused step
//! the server serves with, the task's rules, burn's actor — within 1e-5
//! relative, on the shipped model and on fresh models of the other tasks,
//! layouts, drift inputs and NUNO^R; a model the exporter cannot write is
//! refused by name, before any file is written.

mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::ActorConfig;
use nuno::artifact::{
    DynamicsProvenance, ModelFolder, NamedTensors, PolicyProvenance, load_model_policy,
    safetensors_bytes, save_dynamics, save_ensemble, save_policy,
};
use nuno::data::{GenerateConfig, generate, read_system_dataset};
use nuno::ensemble::{EnsembleConfig, fit_ensemble};
use nuno::envs::{MujocoTask, System, SystemSpec, TaskConfig, TaskName};
use nuno::export::export_onnx;
use nuno::infer::Kernel;
use nuno::nn::to_f32_vec;
use nuno::sde::{DriftInputs, DynamicsSpec, NeuralSde, PhysicalScales, SdeConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Batch sizes over the fused step's row loop, its gemm path and several tiles.
const BATCHES: [usize; 4] = [1, 7, 64, 300];

fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random")
}

fn normal(n: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    (0..n).map(|_| rng.sample(StandardNormal)).collect()
}

/// A freshly initialised model of `task` (scales measured on a little random
/// data), with a random policy beside it, saved in `dir`.
fn fresh_model(dir: &Path, task: TaskConfig, reward_model: bool, drift_inputs: DriftInputs) {
    let device = Device::flex();
    let simulator = MujocoTask::new(&task).unwrap();
    let (obs_dim, act_dim) = (simulator.obs_dim(), simulator.act_dim());
    let policy = nuno::agent::PortableActor::rlkit_random(obs_dim, act_dim, &[64, 64], 3);
    let data = generate(
        &GenerateConfig::new(task.clone(), "random", 2000, 3),
        &policy,
        "test",
        &|_| {},
    )
    .unwrap();
    let spec = DynamicsSpec {
        obs_dim,
        act_dim,
        split: simulator.state_split(),
        dt: simulator.dt(),
    };
    let scales = PhysicalScales::measure(&data, &spec, &Default::default());
    let mut config = SdeConfig::new();
    (config.reward_model, config.drift_inputs) = (reward_model, drift_inputs);
    let model = NeuralSde::init(spec, scales, config, &device);
    let provenance = DynamicsProvenance {
        task: Some(task.clone()),
        ..Default::default()
    };
    save_dynamics(dir, &model, provenance).unwrap();
    let actor =
        ActorConfig::new(obs_dim, act_dim, vec![-1.0; act_dim], vec![1.0; act_dim]).init(&device);
    let system = System::Task(task);
    save_policy(dir, "policy", &actor, &system, PolicyProvenance::default()).unwrap();
}

fn put(tensors: &mut NamedTensors, name: &str, shape: &[usize], values: Vec<f32>) {
    tensors.insert(name.to_string(), (shape.to_vec(), values));
}

/// Observations near the data (the dataset's rows plus a little noise, some
/// far off), actions partly outside the box (the step clips them), and noise;
/// with what the server's code makes of them.
fn cases(dir: &Path, out: &Path, seed: u64) {
    let device = Device::flex();
    let folder = ModelFolder::load(dir, &device).unwrap();
    let system = folder.system().unwrap().unwrap();
    let rules = folder.rules(&system).unwrap();
    let fused = folder.dynamics(Kernel::Fused);
    let (obs_dim, act_dim, state_dim) = (fused.obs_dim(), fused.act_dim(), fused.state_dim());
    let (actor, _) = load_model_policy(dir, obs_dim, act_dim, &device)
        .unwrap()
        .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut tensors = NamedTensors::new();
    for batch in BATCHES {
        let mut obs = normal(batch * obs_dim, &mut rng);
        obs.iter_mut().for_each(|x| *x *= 0.3);
        if let ModelFolder::NeuralSde { model, .. } = &folder {
            // About the data's mean, so the rules see upright and fallen states.
            let mean = &model.constants.scales.normalizer.state.mean;
            for (i, x) in obs.iter_mut().enumerate() {
                *x += mean[i % obs_dim];
            }
        }
        let unclipped: Vec<f32> = normal(batch * act_dim, &mut rng);
        let actions: Vec<f32> = unclipped.iter().map(|a| a.clamp(-1.0, 1.0)).collect();
        let noise = normal(batch * state_dim, &mut rng);
        let step = fused.step(&fused.states_from_observations(&obs), &actions, &noise);

        let observed = |values: &[f32]| -> Vec<f32> {
            (values.chunks_exact(state_dim))
                .flat_map(|row| row[..obs_dim].to_vec())
                .collect()
        };
        let next_obs = observed(&step.next_states);
        let mut rewards = Vec::with_capacity(batch);
        let mut terminals = Vec::with_capacity(batch);
        for b in 0..batch {
            let row = |v: &[f32], w: usize| v[b * w..(b + 1) * w].to_vec();
            let next = row(&next_obs, obs_dim);
            rewards.push(if fused.learns_reward() {
                step.next_states[b * state_dim + obs_dim]
            } else {
                rules.reward(&row(&obs, obs_dim), &row(&actions, act_dim), &next)
            });
            terminals.push(if rules.terminal(&next) { 1.0 } else { 0.0 });
        }
        let policy_noise = normal(batch * act_dim, &mut rng);
        let tensor = |v: &[f32], w: usize| {
            Tensor::<2>::from_data(TensorData::new(v.to_vec(), [batch, w]), &device)
        };
        let sample = actor.sample(tensor(&obs, obs_dim), tensor(&policy_noise, act_dim));
        let deterministic = actor.mean_action(tensor(&obs, obs_dim));

        let at = |name: &str| format!("{batch}/{name}");
        let (o, a, s) = (obs_dim, act_dim, state_dim);
        put(&mut tensors, &at("in/observation"), &[batch, o], obs);
        put(&mut tensors, &at("in/action"), &[batch, a], unclipped);
        put(&mut tensors, &at("in/noise"), &[batch, s], noise);
        put(
            &mut tensors,
            &at("in/policy_noise"),
            &[batch, a],
            policy_noise,
        );
        put(
            &mut tensors,
            &at("mean"),
            &[batch, o],
            observed(&step.means),
        );
        put(
            &mut tensors,
            &at("sigma"),
            &[batch, o],
            observed(&step.sigma),
        );
        put(
            &mut tensors,
            &at("h_eta"),
            &[batch, o],
            observed(&step.h_eta),
        );
        put(&mut tensors, &at("next_state"), &[batch, o], next_obs);
        put(&mut tensors, &at("eta"), &[batch], step.eta);
        put(&mut tensors, &at("reward"), &[batch], rewards);
        put(&mut tensors, &at("terminal"), &[batch], terminals);
        let (sampled, log_prob) = (to_f32_vec(sample.action), to_f32_vec(sample.log_prob));
        put(&mut tensors, &at("sampled_action"), &[batch, a], sampled);
        put(&mut tensors, &at("log_prob"), &[batch], log_prob);
        put(
            &mut tensors,
            &at("deterministic_action"),
            &[batch, a],
            to_f32_vec(deterministic),
        );
    }
    let bytes = safetensors_bytes(&tensors, None).unwrap();
    std::fs::write(out.join("cases.safetensors"), bytes).unwrap();
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv with onnxruntime (`make venv`); `make test` runs it"
)]
fn onnx_runtime_steps_and_acts_as_the_server_does() {
    let root = tempfile::tempdir().unwrap();
    let fresh = [
        // NeoRL's layout: the forward reward is root x's finite difference.
        (
            "walker2d-neorl-reward-pose",
            TaskConfig::neorl(TaskName::Walker2d),
            true,
            DriftInputs::Pose,
        ),
        (
            "halfcheetah-d4rl",
            TaskConfig::d4rl(TaskName::HalfCheetah),
            false,
            DriftInputs::ZScores,
        ),
        (
            "hopper-neorl-pose",
            TaskConfig::neorl(TaskName::Hopper),
            false,
            DriftInputs::Pose,
        ),
    ];
    let mut models = vec![("hopper-random-shipped".to_string(), shipped())];
    for (name, task, reward_model, drift_inputs) in fresh {
        let dir = root.path().join("models").join(name);
        fresh_model(&dir, task, reward_model, drift_inputs);
        models.push((name.to_string(), dir));
    }
    for (seed, (name, dir)) in models.iter().enumerate() {
        let out = root.path().join("onnx").join(name);
        let contract = export_onnx(dir, &out).unwrap();
        assert_eq!(contract.opset, 17);
        assert!(
            contract.policy.is_some(),
            "{name}: the policy beside the model"
        );
        cases(dir, &out, seed as u64);
    }
    common::run_python("onnx_export.py", &[root.path().join("onnx")], root.path());
}

/// A neural SDE of the pendulum described in `examples/pendulum` (a system
/// file, whose reward is an expression), fitted on nothing: random weights.
fn system_file_model(dir: &Path) {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/pendulum");
    let system = System::File(Arc::new(
        SystemSpec::read(&example.join("system.toml")).unwrap(),
    ));
    let data = read_system_dataset(&example.join("log.csv"), None, &system).unwrap();
    let shape = system.shape().unwrap();
    let spec = DynamicsSpec {
        obs_dim: shape.obs_dim,
        act_dim: shape.act_dim,
        split: shape.split,
        dt: shape.dt,
    };
    let scales = PhysicalScales::measure(&data, &spec, &Default::default());
    let model = NeuralSde::init(spec, scales, SdeConfig::new(), &Device::flex());
    let provenance = DynamicsProvenance {
        system: system.file_text(),
        ..Default::default()
    };
    save_dynamics(dir, &model, provenance).unwrap();
}

/// MOPO's ensemble, two epochs on a little hopper data.
fn ensemble_model(dir: &Path) {
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let policy = nuno::agent::PortableActor::rlkit_random(11, 3, &[32, 32], 0);
    let config = GenerateConfig::new(task.clone(), "random", 1000, 0);
    let data = generate(&config, &policy, "test", &|_| {}).unwrap();
    let config = EnsembleConfig::new()
        .with_members(3)
        .with_elites(2)
        .with_hidden(vec![16, 16])
        .with_weight_decay(vec![2.5e-5, 5e-5, 1e-4])
        .with_max_epochs(Some(2));
    let no_checkpoints = &mut |_: &_| Ok(());
    let fit = fit_ensemble(
        &data,
        &config,
        Kernel::Fused,
        &Device::flex(),
        None,
        no_checkpoints,
    );
    save_ensemble(dir, &fit.unwrap(), &config, &System::Task(task), None).unwrap();
}

#[test]
fn what_cannot_be_exported_is_refused_by_name_and_nothing_is_written() {
    let root = tempfile::tempdir().unwrap();
    let (ensemble, pendulum) = (root.path().join("mopo"), root.path().join("pendulum"));
    ensemble_model(&ensemble);
    system_file_model(&pendulum);
    let cases = [
        (root.path().join("nothing-here"), "nothing-here"),
        (ensemble, "Gaussian ensemble"),
        (pendulum, "system file"),
    ];
    for (dir, named) in cases {
        let out = root.path().join("out");
        let err = export_onnx(&dir, &out).unwrap_err();
        assert!(err.to_string().contains(named), "{err} should name {named}");
        assert!(
            !out.exists(),
            "an export that failed left {}",
            out.display()
        );
    }
}

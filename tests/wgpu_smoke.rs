//! burn's wgpu backend runs the same model code as the CPU: a step matches the
//! flex backend, and fitting steps run. Built only with `--features wgpu`
//! (`make check-wgpu`); CI's default build does not pay for the compile.
#![cfg(feature = "wgpu")]

use burn::module::Module;
use burn::tensor::{Tensor, TensorData};
use nuno::artifact::{collect_tensors, load_tensors};
use nuno::envs::{MujocoTask, TaskConfig, TaskName};
use nuno::sde::{
    ComputeDevice, DynamicsSpec, FitConfig, LossConfig, NeuralSde, PhysicalScales, SdeConfig, fit,
};

#[test]
fn wgpu_matches_cpu_and_fits() {
    let task = MujocoTask::new(&TaskConfig::d4rl(TaskName::Hopper)).unwrap();
    let spec = DynamicsSpec {
        obs_dim: 11,
        act_dim: 3,
        split: task.state_split(),
        dt: task.dt(),
    };
    let policy = nuno::agent::PortableActor::rlkit_random(11, 3, &[32], 0);
    let config =
        nuno::data::GenerateConfig::new(TaskConfig::d4rl(TaskName::Hopper), "random", 3000, 0);
    let dataset = nuno::data::generate(&config, &policy, "smoke", &|_| {}).unwrap();
    let cpu = ComputeDevice::Cpu.device().unwrap();
    let gpu = ComputeDevice::Wgpu.device().unwrap();
    let scales = PhysicalScales::measure(&dataset, &spec, &Default::default());
    let model = NeuralSde::init(spec.clone(), scales, SdeConfig::new(), &cpu);
    let on_gpu = load_tensors(
        model.clone().to_device(&gpu),
        &collect_tensors(&model),
        &gpu,
    )
    .unwrap();

    let states: Vec<f32> = dataset.observations.iter().take(64 * 11).copied().collect();
    let actions: Vec<f32> = dataset.actions.iter().take(64 * 3).copied().collect();
    let run = |m: &NeuralSde, device: &burn::tensor::Device| {
        let s = Tensor::<2>::from_data(TensorData::new(states.clone(), [64, 11]), device);
        let a = Tensor::<2>::from_data(TensorData::new(actions.clone(), [64, 3]), device);
        let e = Tensor::<2>::zeros([64, 11], device);
        let (next, terms) = m.step(s, a, e);
        let flat = |t: Tensor<2>| t.into_data().convert::<f32>().try_to_vec::<f32>().unwrap();
        (flat(next), flat(terms.eta))
    };
    let (next_cpu, eta_cpu) = run(&model, &cpu);
    let (next_gpu, eta_gpu) = run(&on_gpu, &gpu);
    for (a, b) in next_cpu
        .iter()
        .zip(&next_gpu)
        .chain(eta_cpu.iter().zip(&eta_gpu))
    {
        assert!(
            (a - b).abs() <= 1e-4 * (1.0 + a.abs()),
            "cpu {a} vs wgpu {b}"
        );
    }

    let (train, valid) = dataset.split_by_trajectory(0.2, 0);
    let mut fit_config = FitConfig::new(SdeConfig::new(), LossConfig::new());
    fit_config.max_steps = 20;
    fit_config.eval_every = 10;
    let (_, summary) = fit(&train, &valid, spec, &fit_config, &gpu, &mut |_| {}).unwrap();
    assert_eq!(summary.steps, 20);
    assert!(summary.best_valid_nll.is_finite());
}

//! The hand-written input gradient of η (needed because burn 0.22 cannot take
//! a gradient of a gradient) against burn's autodiff `x.grad`, and the
//! parameter gradients of a loss built on it against central finite
//! differences, in f64. Its own test binary: it sets the device's float type.

use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use nuno::artifact::{collect_tensors, load_tensors};
use nuno::nn::{Activation, Mlp, MlpConfig};

fn device_f64() -> Device {
    static DEVICE: std::sync::OnceLock<Device> = std::sync::OnceLock::new();
    DEVICE
        .get_or_init(|| {
            let mut device = Device::flex();
            device
                .configure(FloatDType::F64)
                .expect("flex supports f64");
            device
        })
        .clone()
}

fn values(t: Tensor<2>) -> Vec<f64> {
    t.into_data().convert::<f64>().try_to_vec().unwrap()
}

fn inputs(device: &Device) -> Tensor<2> {
    let x: Vec<f64> = (0..4 * 5).map(|i| ((i as f64) * 0.37).sin()).collect();
    Tensor::from_data(TensorData::new(x, [4, 5]), device)
}

#[test]
fn input_gradient_matches_autodiff_for_every_activation() {
    let device = device_f64().autodiff();
    for activation in [Activation::Swish, Activation::Tanh, Activation::Relu] {
        let mlp: Mlp = MlpConfig::new(5, vec![16, 8], 1, activation).init(&device);
        let x = inputs(&device).require_grad();
        let (y, manual) = mlp.forward_with_input_grad(x.clone());
        let autodiff = x.grad(&y.sum().backward()).unwrap();
        let (manual, autodiff) = (values(manual), values(autodiff));
        for (m, a) in manual.iter().zip(&autodiff) {
            assert!(
                (m - a).abs() <= 1e-12 * (1.0 + a.abs()),
                "{activation:?}: manual {m} vs autodiff {a}"
            );
        }
        let plain = values(mlp.forward(inputs(&device)));
        let (with_grad, _) = mlp.forward_with_input_grad(inputs(&device));
        assert_eq!(plain, values(with_grad));
    }
}

/// L = Σ ‖∇ₓ NN(x)‖²: a loss on the input gradient, as L_grad is.
fn gradient_loss(mlp: &Mlp, device: &Device) -> Tensor<1> {
    let (_, grad) = mlp.forward_with_input_grad(inputs(device));
    grad.square().sum()
}

#[test]
fn parameter_gradients_of_an_input_gradient_loss_match_finite_differences() {
    let device = device_f64().autodiff();
    let mlp: Mlp = MlpConfig::new(5, vec![8, 8], 1, Activation::Swish).init(&device);
    let grads = gradient_loss(&mlp, &device).backward();
    let tensors = collect_tensors(&mlp);
    let h = 1e-6;
    let mut checked = 0;
    for (name, (shape, base)) in &tensors {
        // The autodiff gradient of this parameter, in the collector's order.
        let param_grad: Vec<f64> = {
            let mut found = None;
            for (layer_index, layer) in mlp.layers.iter().enumerate() {
                // A parameter the loss does not depend on (the last bias) has no gradient: 0.
                if name == &format!("layers.{layer_index}.weight") {
                    let grad = layer.weight.val().grad(&grads);
                    found = Some(grad.map_or(vec![0.0; base.len()], values));
                } else if name == &format!("layers.{layer_index}.bias") {
                    let grad = layer.bias.as_ref().unwrap().val().grad(&grads);
                    found = Some(grad.map_or(vec![0.0; base.len()], |g| {
                        g.into_data().convert::<f64>().try_to_vec().unwrap()
                    }));
                }
            }
            found.unwrap_or_else(|| panic!("no gradient for {name}"))
        };
        for index in [0, base.len() / 2, base.len() - 1] {
            let loss_at = |delta: f64| {
                let mut perturbed = tensors.clone();
                let entry = perturbed.get_mut(name).unwrap();
                entry.1[index] = (f64::from(base[index]) + delta) as f32;
                let model = load_tensors(mlp.clone(), &perturbed, &device).unwrap();
                gradient_loss(&model, &device).into_scalar::<f64>()
            };
            // Perturbations go through f32 storage: use the step actually taken.
            let up = f64::from((f64::from(base[index]) + h) as f32) - f64::from(base[index]);
            let down = f64::from(base[index]) - f64::from((f64::from(base[index]) - h) as f32);
            let numeric = (loss_at(h) - loss_at(-h)) / (up + down);
            let analytic = param_grad[index];
            assert!(
                (numeric - analytic).abs() <= 1e-3 * (1.0 + analytic.abs()),
                "{name}[{index}] {shape:?}: finite difference {numeric} vs autodiff {analytic}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 18, "three entries of each of the six parameters");
}

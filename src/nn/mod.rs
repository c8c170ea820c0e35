//! Network building blocks shared by the neural SDE and the SAC agent.

mod adam;
mod mlp;

pub use adam::{Adam, AdamState, AdamStep, Moments, clip_to_norm};
pub use mlp::{Activation, Mlp, MlpConfig};

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Bool, Device, Int, Tensor, TensorData};
use std::sync::Mutex;

use rand::Rng;
use rand_distr::StandardNormal;

/// Standard normal noise of the given shape, from our own seeded generator
/// (burn's random tensors would not follow the caller's seed).
pub fn normal<const D: usize>(shape: [usize; D], rng: &mut impl Rng, device: &Device) -> Tensor<D> {
    let values = standard_normal(shape.iter().product(), rng);
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// `n` standard normal draws, in the order [`normal`] fills its tensor.
pub fn standard_normal(n: usize, rng: &mut impl Rng) -> Vec<f32> {
    let mut values = Vec::with_capacity(n);
    fill_standard_normal(&mut values, n, rng);
    values
}

/// [`standard_normal`] into `values` (resized to `n`), reusing its memory.
pub fn fill_standard_normal(values: &mut Vec<f32>, n: usize, rng: &mut impl Rng) {
    values.clear();
    values.extend((0..n).map(|_| rng.sample::<f32, _>(StandardNormal)));
}

/// Seeds burn's initialiser with `seed`, runs `init` and draws every parameter it
/// built, all under a process-wide lock. burn's generator is global: two fits (or
/// tests) seeding and drawing at once would interleave, and neither would get the
/// weights its seed gives alone. burn 0.22 draws a parameter's values lazily, at
/// its first use, so they are drawn here, before the lock is released; otherwise
/// another thread's seed would decide them.
pub fn seeded_init<T: Initialised>(device: &Device, seed: u64, init: impl FnOnce() -> T) -> T {
    static INIT: Mutex<()> = Mutex::new(());
    let _guard = INIT.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    device.seed(seed);
    let built = init();
    built.draw_parameters();
    built
}

/// What [`seeded_init`] builds: a module, or a struct of modules, whose lazily
/// initialised parameters can be drawn at once.
pub trait Initialised {
    /// Draws the values of every parameter not yet drawn.
    fn draw_parameters(&self);
}

impl<M: Module> Initialised for M {
    fn draw_parameters(&self) {
        struct Draw;
        impl ModuleVisitor for Draw {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                param.val();
            }
            fn visit_int<const D: usize>(&mut self, param: &Param<Tensor<D, Int>>) {
                param.val();
            }
            fn visit_bool<const D: usize>(&mut self, param: &Param<Tensor<D, Bool>>) {
                param.val();
            }
        }
        self.visit(&mut Draw);
    }
}

/// Row-major `values` as a `[values.len() / width, width]` tensor on `device`:
/// a batch's column group (observations, actions, rewards) as the networks read it.
pub fn rows_tensor(values: &[f32], width: usize, device: &Device) -> Tensor<2> {
    let shape = [values.len() / width.max(1), width];
    Tensor::from_data(TensorData::new(values.to_vec(), shape), device)
}

/// A tensor's values as f32, row-major (converting from the device's float type).
pub fn to_f32_vec<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    // After `convert::<f32>` the element type matches, so `to_vec` cannot fail.
    tensor
        .into_data()
        .convert::<f32>()
        .try_to_vec()
        .unwrap_or_default()
}

/// Every float parameter of `module`, flattened, off the autodiff graph, in
/// visiting order.
fn flat_params<M: Module>(module: &M) -> Vec<Tensor<1>> {
    struct Collect(Vec<Tensor<1>>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.push(param.val().inner().flatten(0, D - 1));
        }
    }
    let mut params = Collect(Vec::new());
    module.visit(&mut params);
    params.0
}

/// `target` holding `source`'s values (same module structure), on `target`'s
/// device, its parameter ids and whether each trains kept: a restored
/// checkpoint's weights into a module that trains.
pub fn assign_params<M: Module>(target: M, source: &M) -> M {
    struct Assign(std::vec::IntoIter<Tensor<1>>);
    impl ModuleMapper for Assign {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let Some(value) = self.0.next() else {
                return param;
            };
            let (id, old) = (param.id, param.val());
            let require_grad = old.is_require_grad();
            let value: Tensor<D> = value.to_device(&old.device()).reshape(old.dims());
            // A trained parameter lives on the autodiff device, which
            // `device()` does not name.
            let value = if require_grad {
                value.autodiff().set_require_grad(true)
            } else {
                value
            };
            Param::initialized(id, value)
        }
    }
    target.map(&mut Assign(flat_params(source).into_iter()))
}

/// `grads` of `module`'s parameters by module path (`layers.0.weight`, ...):
/// what a hand-written gradient is compared with.
pub fn gradients_by_path<M: Module>(
    module: &M,
    grads: &burn::optim::GradientsParams,
) -> std::collections::BTreeMap<String, Vec<f32>> {
    struct Collect<'a> {
        grads: &'a burn::optim::GradientsParams,
        path: Vec<String>,
        out: std::collections::BTreeMap<String, Vec<f32>>,
    }
    impl ModuleVisitor for Collect<'_> {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if let Some(grad) = self.grads.get::<D>(param.id) {
                self.out.insert(self.path.join("."), to_f32_vec(grad));
            }
        }
    }
    let mut collect = Collect {
        grads,
        path: Vec::new(),
        out: Default::default(),
    };
    module.visit(&mut collect);
    collect.out
}

/// Polyak averaging `θ̄ ← τ·θ + (1 − τ)·θ̄` of `target` towards `online`
/// (same module structure), on `target`'s device and off the autodiff graph.
pub fn polyak_update<M: Module>(target: M, online: &M, tau: f64) -> M {
    struct Blend {
        online: std::vec::IntoIter<Tensor<1>>,
        tau: f64,
    }
    impl ModuleMapper for Blend {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let Some(online) = self.online.next() else {
                return param;
            };
            let (id, old) = (param.id, param.val());
            let device = old.device();
            let online: Tensor<D> = online.to_device(&device).reshape(old.dims());
            let blended = online * self.tau + old.detach() * (1.0 - self.tau);
            Param::initialized(id, blended)
        }
    }
    target.map(&mut Blend {
        online: flat_params(online).into_iter(),
        tau,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn weights(mlp: &Mlp) -> Vec<f32> {
        flat_params(mlp).into_iter().flat_map(to_f32_vec).collect()
    }

    /// burn draws a `Param` at its first use: if `seeded_init` returned the
    /// module undrawn, the re-seed between building and reading (another
    /// thread's fit, in the suite) would decide the weights.
    #[test]
    fn seeded_init_draws_the_weights_under_its_seed() {
        let device = Device::flex();
        let config = MlpConfig::new(3, vec![8], 2, Activation::Relu);
        let built = seeded_init(&device, 7, || config.init(&device));
        device.seed(99);
        let _other = Tensor::<2>::random([4, 4], burn::tensor::Distribution::Default, &device);
        let read_later = weights(&built);
        let read_at_once = weights(&seeded_init(&device, 7, || config.init(&device)));
        assert_eq!(read_later, read_at_once);
        let other_seed = weights(&seeded_init(&device, 8, || config.init(&device)));
        assert_ne!(read_later, other_seed);
    }
}

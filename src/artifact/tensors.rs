//! A burn module's float parameters as named f32 tensors, and back: the names
//! are the module paths (`g_net.layers.0.weight`), stable across runs, so the
//! safetensors files can be read by any safetensors reader.

use std::collections::BTreeMap;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Device, Tensor, TensorData};

use super::ArtifactError;

/// Named f32 tensors: name → (shape, values).
pub type NamedTensors = BTreeMap<String, (Vec<usize>, Vec<f32>)>;

#[derive(Default)]
struct Collector {
    path: Vec<String>,
    tensors: NamedTensors,
}

impl ModuleVisitor for Collector {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let tensor = param.val();
        let shape = tensor.dims().to_vec();
        let values = tensor
            .into_data()
            .convert::<f32>()
            .try_to_vec()
            .unwrap_or_default();
        self.tensors.insert(self.path.join("."), (shape, values));
    }
}

/// Every float parameter of `module`, by path.
pub fn collect_tensors<M: Module>(module: &M) -> NamedTensors {
    let mut collector = Collector::default();
    module.visit(&mut collector);
    collector.tensors
}

struct Loader<'a> {
    path: Vec<String>,
    tensors: &'a NamedTensors,
    device: Device,
    used: Vec<String>,
    error: Option<ArtifactError>,
}

impl ModuleMapper for Loader<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let name = self.path.join(".");
        let expected = param.val().dims().to_vec();
        let Some((shape, values)) = self.tensors.get(&name) else {
            self.error.get_or_insert(ArtifactError::MissingTensor(name));
            return param;
        };
        if *shape != expected {
            self.error.get_or_insert(ArtifactError::TensorShape {
                name,
                expected,
                got: shape.clone(),
            });
            return param;
        }
        let id = param.id;
        self.used.push(name);
        // Keep whether the parameter trains, so a module loaded onto an autodiff device still learns.
        let require_grad = param.val().is_require_grad();
        let tensor =
            Tensor::from_data(TensorData::new(values.clone(), shape.clone()), &self.device);
        Param::initialized(id, tensor.set_require_grad(require_grad))
    }
}

/// Replaces every float parameter of `module` with the tensor of the same
/// path; every parameter must be present with its shape, and no tensor may be left over.
pub fn load_tensors<M: Module>(
    module: M,
    tensors: &NamedTensors,
    device: &Device,
) -> Result<M, ArtifactError> {
    let mut loader = Loader {
        path: Vec::new(),
        tensors,
        device: device.clone(),
        used: Vec::new(),
        error: None,
    };
    let module = module.map(&mut loader);
    if let Some(error) = loader.error {
        return Err(error);
    }
    if let Some(extra) = tensors.keys().find(|name| !loader.used.contains(name)) {
        return Err(ArtifactError::UnexpectedTensor(extra.clone()));
    }
    Ok(module)
}

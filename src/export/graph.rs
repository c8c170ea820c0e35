//! A small builder of ONNX graphs over the generated messages: inputs and
//! outputs `[batch, width]`, constants as initializers, one node per call,
//! and an [`Mlp`] as its chain of MatMul, Add and activation nodes.

use super::proto::onnx::{
    AttributeProto, GraphProto, ModelProto, NodeProto, OperatorSetIdProto, TensorProto,
    TensorShapeProto, TypeProto, ValueInfoProto, attribute_proto::AttributeType,
    tensor_proto::DataType, tensor_shape_proto::Dimension, tensor_shape_proto::dimension,
    type_proto,
};
use crate::nn::{Activation, Mlp, to_f32_vec};

/// The operator set every exported graph is written against (ONNX 1.12,
/// 2022: every runtime of the last years reads it).
pub const OPSET: i64 = 17;
/// The IR version that goes with [`OPSET`].
pub const IR_VERSION: i64 = 8;
/// The name of the leading (free) dimension of every input and output.
pub const BATCH: &str = "batch";

/// A tensor of the graph, by name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Value(String);

/// An element type of an input or output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Elem {
    F32,
    Bool,
}

impl Elem {
    fn data_type(self) -> DataType {
        match self {
            Elem::F32 => DataType::Float,
            Elem::Bool => DataType::Bool,
        }
    }
}

/// One graph under construction.
#[derive(Debug, Default)]
pub struct Graph {
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    inputs: Vec<ValueInfoProto>,
    outputs: Vec<ValueInfoProto>,
    names: usize,
}

/// `[batch, width]` (or `[batch]` without a width) of `elem`.
fn value_info(name: &str, width: Option<usize>, elem: Elem) -> ValueInfoProto {
    let batch = dimension::Value::DimParam(BATCH.to_string());
    let mut dims = vec![batch];
    dims.extend(width.map(|w| dimension::Value::DimValue(w as i64)));
    let shape = TensorShapeProto {
        dim: dims
            .into_iter()
            .map(|value| Dimension {
                value: Some(value),
                ..Default::default()
            })
            .collect(),
    };
    ValueInfoProto {
        name: Some(name.to_string()),
        r#type: Some(TypeProto {
            value: Some(type_proto::Value::TensorType(type_proto::Tensor {
                elem_type: Some(elem.data_type() as i32),
                shape: Some(shape),
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// An integer-list attribute (ReduceMin's `axes` at opset 17).
pub fn ints(name: &str, values: &[i64]) -> AttributeProto {
    AttributeProto {
        name: Some(name.to_string()),
        r#type: Some(AttributeType::Ints as i32),
        ints: values.to_vec(),
        ..Default::default()
    }
}

/// An integer attribute (`axis`, `keepdims`, `to`).
pub fn int(name: &str, value: i64) -> AttributeProto {
    AttributeProto {
        name: Some(name.to_string()),
        r#type: Some(AttributeType::Int as i32),
        i: Some(value),
        ..Default::default()
    }
}

impl Graph {
    fn fresh(&mut self, stem: &str) -> String {
        self.names += 1;
        format!("{stem}_{}", self.names)
    }

    /// An input `[batch, width]` of f32.
    pub fn input(&mut self, name: &str, width: usize) -> Value {
        self.inputs.push(value_info(name, Some(width), Elem::F32));
        Value(name.to_string())
    }

    /// Makes `value` the output `name`, `[batch, width]` or `[batch]`.
    pub fn output(&mut self, value: &Value, name: &str, width: Option<usize>, elem: Elem) {
        self.nodes.push(NodeProto {
            input: vec![value.0.clone()],
            output: vec![name.to_string()],
            name: Some(format!("{name}_out")),
            op_type: Some("Identity".to_string()),
            ..Default::default()
        });
        self.outputs.push(value_info(name, width, elem));
    }

    /// A constant of shape `dims`, its values' little-endian bytes in `raw`.
    fn initializer(
        &mut self,
        stem: &str,
        dims: &[usize],
        data_type: DataType,
        raw: Vec<u8>,
    ) -> Value {
        let name = self.fresh(stem);
        self.initializers.push(TensorProto {
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: Some(data_type as i32),
            raw_data: Some(raw),
            name: Some(name.clone()),
            ..Default::default()
        });
        Value(name)
    }

    /// An f32 constant of shape `dims`.
    pub fn constant(&mut self, values: &[f32], dims: &[usize]) -> Value {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.initializer("const", dims, DataType::Float, raw)
    }

    /// An i64 constant (indices, shapes, axes).
    pub fn indices(&mut self, values: &[i64]) -> Value {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.initializer("index", &[values.len()], DataType::Int64, raw)
    }

    /// A row vector `[width]` that broadcasts over `[batch, width]`.
    pub fn row(&mut self, values: &[f32]) -> Value {
        self.constant(values, &[values.len()])
    }

    /// A scalar that broadcasts over anything.
    pub fn scalar(&mut self, value: f32) -> Value {
        self.constant(&[value], &[])
    }

    /// One node of `op` on `inputs`; its single output.
    pub fn op(&mut self, op: &str, inputs: &[&Value], attributes: Vec<AttributeProto>) -> Value {
        let out = self.fresh(&op.to_lowercase());
        self.nodes.push(NodeProto {
            input: inputs.iter().map(|v| v.0.clone()).collect(),
            output: vec![out.clone()],
            name: Some(format!("{out}_node")),
            op_type: Some(op.to_string()),
            attribute: attributes,
            ..Default::default()
        });
        Value(out)
    }

    pub fn add(&mut self, a: &Value, b: &Value) -> Value {
        self.op("Add", &[a, b], vec![])
    }

    pub fn sub(&mut self, a: &Value, b: &Value) -> Value {
        self.op("Sub", &[a, b], vec![])
    }

    pub fn mul(&mut self, a: &Value, b: &Value) -> Value {
        self.op("Mul", &[a, b], vec![])
    }

    pub fn div(&mut self, a: &Value, b: &Value) -> Value {
        self.op("Div", &[a, b], vec![])
    }

    /// Columns `columns` of `[batch, width]` rows, in that order.
    pub fn columns(&mut self, x: &Value, columns: &[usize]) -> Value {
        let index: Vec<i64> = columns.iter().map(|&c| c as i64).collect();
        let index = self.indices(&index);
        self.op("Gather", &[x, &index], vec![int("axis", 1)])
    }

    /// `values` side by side along the columns.
    pub fn concat(&mut self, values: &[&Value]) -> Value {
        self.op("Concat", values, vec![int("axis", 1)])
    }

    /// `x` reshaped to `shape` (−1 for the batch).
    pub fn reshape(&mut self, x: &Value, shape: &[i64]) -> Value {
        let shape = self.indices(shape);
        self.op("Reshape", &[x, &shape], vec![])
    }

    /// The sum over `axis`, dropping it.
    pub fn sum(&mut self, x: &Value, axis: i64) -> Value {
        let axes = self.indices(&[axis]);
        self.op("ReduceSum", &[x, &axes], vec![int("keepdims", 0)])
    }

    /// `mlp(x)`: each layer's `x·W + b`, the activation between layers.
    pub fn mlp(&mut self, mlp: &Mlp, x: &Value) -> Value {
        let last = mlp.layers.len() - 1;
        let mut h = x.clone();
        for (i, layer) in mlp.layers.iter().enumerate() {
            let [d_in, d_out] = layer.weight.val().dims();
            let weight = self.constant(&to_f32_vec(layer.weight.val()), &[d_in, d_out]);
            h = self.op("MatMul", &[&h, &weight], vec![]);
            if let Some(bias) = &layer.bias {
                let bias = self.row(&to_f32_vec(bias.val()));
                h = self.add(&h, &bias);
            }
            if i < last {
                h = self.activation(mlp.activation, &h);
            }
        }
        h
    }

    fn activation(&mut self, activation: Activation, z: &Value) -> Value {
        match activation {
            Activation::Relu => self.op("Relu", &[z], vec![]),
            Activation::Tanh => self.op("Tanh", &[z], vec![]),
            // swish(z) = z·sigmoid(z): opset 17 has no Swish.
            Activation::Swish => {
                let s = self.sigmoid(z);
                self.mul(z, &s)
            }
        }
    }

    /// sigmoid(z) = 1/(1 + e^−z), nuno's own form. ONNX Runtime's Sigmoid
    /// approximates to ≈ 1e-8 absolute, so its far tail (h(η) on the data,
    /// ≈ 1e-6) would be off by percents.
    pub fn sigmoid(&mut self, z: &Value) -> Value {
        let minus_z = self.op("Neg", &[z], vec![]);
        let e = self.op("Exp", &[&minus_z], vec![]);
        let one = self.scalar(1.0);
        let denominator = self.add(&one, &e);
        self.div(&one, &denominator)
    }

    /// The model: this graph under `name`, with `doc` as its description.
    pub fn finish(self, name: &str, doc: &str) -> ModelProto {
        ModelProto {
            ir_version: Some(IR_VERSION),
            opset_import: vec![OperatorSetIdProto {
                domain: Some(String::new()),
                version: Some(OPSET),
            }],
            producer_name: Some("nuno".to_string()),
            producer_version: Some(env!("CARGO_PKG_VERSION").to_string()),
            doc_string: Some(doc.to_string()),
            graph: Some(GraphProto {
                node: self.nodes,
                name: Some(name.to_string()),
                initializer: self.initializers,
                input: self.inputs,
                output: self.outputs,
                ..Default::default()
            }),
            ..Default::default()
        }
    }
}

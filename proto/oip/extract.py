"""Writes grpc_predict_v2.binpb: the Open Inference Protocol's gRPC service
(`inference.GRPCInferenceService`, `grpc_predict_v2.proto`) as KServe ships it,
compiled, in its Python package (kserve 0.21.0 on PyPI, Apache-2.0). The bytes
are protoc's FileDescriptorProto of the protocol's own .proto file, wrapped in a
FileDescriptorSet for `build.rs` (tonic-prost-build's `compile_fds`).

Run from the repository root with the test venv: .venv/bin/python proto/oip/extract.py"""

from pathlib import Path

from google.protobuf import descriptor_pb2
from kserve.protocol.grpc import grpc_predict_v2_pb2

proto = descriptor_pb2.FileDescriptorProto.FromString(grpc_predict_v2_pb2.DESCRIPTOR.serialized_pb)
assert proto.name == "grpc_predict_v2.proto" and proto.package == "inference", proto.name
out = Path(__file__).with_name("grpc_predict_v2.binpb")
out.write_bytes(descriptor_pb2.FileDescriptorSet(file=[proto]).SerializeToString())
print(f"wrote {out} ({out.stat().st_size} bytes): {[s.name for s in proto.service]}")

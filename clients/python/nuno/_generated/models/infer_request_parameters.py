from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset






T = TypeVar("T", bound="InferRequestParameters")



@_attrs_define
class InferRequestParameters:
    """ `seed`, `penalty`, `noise_scale` (one particle per row);
    `binary_data_output: true` answers every output in binary.

        Attributes:
            binary_data_output (bool | Unset):
            noise_scale (float | Unset):
            penalty (float | Unset):
            seed (int | Unset):
     """

    binary_data_output: bool | Unset = UNSET
    noise_scale: float | Unset = UNSET
    penalty: float | Unset = UNSET
    seed: int | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        binary_data_output = self.binary_data_output

        noise_scale = self.noise_scale

        penalty = self.penalty

        seed = self.seed


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
        })
        if binary_data_output is not UNSET:
            field_dict["binary_data_output"] = binary_data_output
        if noise_scale is not UNSET:
            field_dict["noise_scale"] = noise_scale
        if penalty is not UNSET:
            field_dict["penalty"] = penalty
        if seed is not UNSET:
            field_dict["seed"] = seed

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        binary_data_output = d.pop("binary_data_output", UNSET)

        noise_scale = d.pop("noise_scale", UNSET)

        penalty = d.pop("penalty", UNSET)

        seed = d.pop("seed", UNSET)

        infer_request_parameters = cls(
            binary_data_output=binary_data_output,
            noise_scale=noise_scale,
            penalty=penalty,
            seed=seed,
        )


        infer_request_parameters.additional_properties = d
        return infer_request_parameters

    @property
    def additional_keys(self) -> list[str]:
        return list(self.additional_properties.keys())

    def __getitem__(self, key: str) -> Any:
        return self.additional_properties[key]

    def __setitem__(self, key: str, value: Any) -> None:
        self.additional_properties[key] = value

    def __delitem__(self, key: str) -> None:
        del self.additional_properties[key]

    def __contains__(self, key: str) -> bool:
        return key in self.additional_properties

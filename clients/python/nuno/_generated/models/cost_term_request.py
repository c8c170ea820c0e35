from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="CostTermRequest")



@_attrs_define
class CostTermRequest:
    """ 
        Attributes:
            observation (int | str): An observation by name or by index.
            target (float):
            weight (float | Unset): Its weight (default 1).
     """

    observation: int | str
    target: float
    weight: float | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        observation: int | str
        observation = self.observation

        target = self.target

        weight = self.weight


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "observation": observation,
            "target": target,
        })
        if weight is not UNSET:
            field_dict["weight"] = weight

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        def _parse_observation(data: object) -> int | str:
            return cast(int | str, data)

        observation = _parse_observation(d.pop("observation"))


        target = d.pop("target")

        weight = d.pop("weight", UNSET)

        cost_term_request = cls(
            observation=observation,
            target=target,
            weight=weight,
        )

        return cost_term_request


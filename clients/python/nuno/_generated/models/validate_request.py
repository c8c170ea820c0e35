from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="ValidateRequest")



@_attrs_define
class ValidateRequest:
    """ 
        Attributes:
            actions (list[list[float]]): Actions to apply, `[horizon][act_dim]` (act_dim: the model's).
            noise_scale (float | Unset): Multiplies the model's noise (default 0: the drift alone).
            particles (int | Unset): Model samples averaged per step (default 1).
            seed (int | Unset): Reset seed of the real task (the start state).
     """

    actions: list[list[float]]
    noise_scale: float | Unset = UNSET
    particles: int | Unset = UNSET
    seed: int | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        actions = []
        for actions_item_data in self.actions:
            actions_item = actions_item_data


            actions.append(actions_item)



        noise_scale = self.noise_scale

        particles = self.particles

        seed = self.seed


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "actions": actions,
        })
        if noise_scale is not UNSET:
            field_dict["noise_scale"] = noise_scale
        if particles is not UNSET:
            field_dict["particles"] = particles
        if seed is not UNSET:
            field_dict["seed"] = seed

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        actions = []
        _actions = d.pop("actions")
        for actions_item_data in (_actions):
            actions_item = cast(list[float], actions_item_data)

            actions.append(actions_item)


        noise_scale = d.pop("noise_scale", UNSET)

        particles = d.pop("particles", UNSET)

        seed = d.pop("seed", UNSET)

        validate_request = cls(
            actions=actions,
            noise_scale=noise_scale,
            particles=particles,
            seed=seed,
        )

        return validate_request


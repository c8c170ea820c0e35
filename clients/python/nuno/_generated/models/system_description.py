from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
  from ..models.system_description_bounds import SystemDescriptionBounds





T = TypeVar("T", bound="SystemDescription")



@_attrs_define
class SystemDescription:
    """ What a system file declares, by name.

        Attributes:
            action_high (list[float]):
            action_low (list[float]):
            actions (list[str]):
            angles (list[str]): Positions the drift sees through cos and sin.
            bounds (SystemDescriptionBounds): Observation → `[low, high]`: an episode ends outside.
            dt (float): Seconds between consecutive observations.
            name (str):
            observations (list[str]):
            pairs (list[list[str]]): `[position, velocity]`: d position/dt = velocity (eq. 8's prior).
            reward (str): `learned` or the reward expression.
     """

    action_high: list[float]
    action_low: list[float]
    actions: list[str]
    angles: list[str]
    bounds: SystemDescriptionBounds
    dt: float
    name: str
    observations: list[str]
    pairs: list[list[str]]
    reward: str
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.system_description_bounds import SystemDescriptionBounds # noqa: PLC0415
        action_high = self.action_high



        action_low = self.action_low



        actions = self.actions



        angles = self.angles



        bounds = self.bounds.to_dict()

        dt = self.dt

        name = self.name

        observations = self.observations



        pairs = []
        for pairs_item_data in self.pairs:
            pairs_item = pairs_item_data


            pairs.append(pairs_item)



        reward = self.reward


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "action_high": action_high,
            "action_low": action_low,
            "actions": actions,
            "angles": angles,
            "bounds": bounds,
            "dt": dt,
            "name": name,
            "observations": observations,
            "pairs": pairs,
            "reward": reward,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.system_description_bounds import SystemDescriptionBounds # noqa: PLC0415
        d = dict(src_dict)
        action_high = cast(list[float], d.pop("action_high"))


        action_low = cast(list[float], d.pop("action_low"))


        actions = cast(list[str], d.pop("actions"))


        angles = cast(list[str], d.pop("angles"))


        bounds = SystemDescriptionBounds.from_dict(d.pop("bounds"))




        dt = d.pop("dt")

        name = d.pop("name")

        observations = cast(list[str], d.pop("observations"))


        pairs = []
        _pairs = d.pop("pairs")
        for pairs_item_data in (_pairs):
            pairs_item = cast(list[str], pairs_item_data)

            pairs.append(pairs_item)


        reward = d.pop("reward")

        system_description = cls(
            action_high=action_high,
            action_low=action_low,
            actions=actions,
            angles=angles,
            bounds=bounds,
            dt=dt,
            name=name,
            observations=observations,
            pairs=pairs,
            reward=reward,
        )


        system_description.additional_properties = d
        return system_description

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

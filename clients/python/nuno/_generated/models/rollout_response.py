from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.trajectory import Trajectory





T = TypeVar("T", bound="RolloutResponse")



@_attrs_define
class RolloutResponse:
    """ 
        Attributes:
            clipped_rows (int): Open-loop action rows (start × step) clipped into the action box.
            horizon (int):
            model (str):
            noise_scale (float): The scale of ε the samples were drawn at: the request's `noise_scale`,
                else the model's own.
            particles (int):
            trajectories (list[Trajectory]): Start `b`'s particle `p` is entry `b·particles + p`.
            threshold (float | None | Unset): The truncation threshold used, if any.
     """

    clipped_rows: int
    horizon: int
    model: str
    noise_scale: float
    particles: int
    trajectories: list[Trajectory]
    threshold: float | None | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.trajectory import Trajectory # noqa: PLC0415
        clipped_rows = self.clipped_rows

        horizon = self.horizon

        model = self.model

        noise_scale = self.noise_scale

        particles = self.particles

        trajectories = []
        for trajectories_item_data in self.trajectories:
            trajectories_item = trajectories_item_data.to_dict()
            trajectories.append(trajectories_item)



        threshold: float | None | Unset
        if isinstance(self.threshold, Unset):
            threshold = UNSET
        else:
            threshold = self.threshold


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "clipped_rows": clipped_rows,
            "horizon": horizon,
            "model": model,
            "noise_scale": noise_scale,
            "particles": particles,
            "trajectories": trajectories,
        })
        if threshold is not UNSET:
            field_dict["threshold"] = threshold

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.trajectory import Trajectory # noqa: PLC0415
        d = dict(src_dict)
        clipped_rows = d.pop("clipped_rows")

        horizon = d.pop("horizon")

        model = d.pop("model")

        noise_scale = d.pop("noise_scale")

        particles = d.pop("particles")

        trajectories = []
        _trajectories = d.pop("trajectories")
        for trajectories_item_data in (_trajectories):
            trajectories_item = Trajectory.from_dict(trajectories_item_data)



            trajectories.append(trajectories_item)


        def _parse_threshold(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        threshold = _parse_threshold(d.pop("threshold", UNSET))


        rollout_response = cls(
            clipped_rows=clipped_rows,
            horizon=horizon,
            model=model,
            noise_scale=noise_scale,
            particles=particles,
            trajectories=trajectories,
            threshold=threshold,
        )


        rollout_response.additional_properties = d
        return rollout_response

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

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.model_kind import ModelKind
from typing import cast






T = TypeVar("T", bound="ModelSummary")



@_attrs_define
class ModelSummary:
    """ One loaded model in brief.

        Attributes:
            act_dim (int):
            action_high (list[float]):
            action_low (list[float]): The action box's lower and upper bounds, `[act_dim]` each: actions
                outside it are clipped into it (or refused with `clip: false`).
            dt (float): Seconds of the task one model step covers.
            has_policy (bool):
            id (str):
            kind (ModelKind): Which kind of dynamics model is served (`kind` in `/v1/models/{id}`).
            layout (str): d4rl or neorl observations; `system` for a system described in a file.
            obs_dim (int):
            reward_model (bool): Rewards come from the model (NUNO^R, the ensemble).
            sample_noise_scale (float): The scale of ε the model samples at unless a request gives `noise_scale`:
                1 is the calibrated Σ; a neural SDE fitted with NUNO's code's convention
                records sqrt(dt).
            task (str): A built-in task (hopper, halfcheetah, walker2d, swimmer, invertedpendulum, ant);
                or the name a system file gives.
     """

    act_dim: int
    action_high: list[float]
    action_low: list[float]
    dt: float
    has_policy: bool
    id: str
    kind: ModelKind
    layout: str
    obs_dim: int
    reward_model: bool
    sample_noise_scale: float
    task: str
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        act_dim = self.act_dim

        action_high = self.action_high



        action_low = self.action_low



        dt = self.dt

        has_policy = self.has_policy

        id = self.id

        kind = self.kind.value

        layout = self.layout

        obs_dim = self.obs_dim

        reward_model = self.reward_model

        sample_noise_scale = self.sample_noise_scale

        task = self.task


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "act_dim": act_dim,
            "action_high": action_high,
            "action_low": action_low,
            "dt": dt,
            "has_policy": has_policy,
            "id": id,
            "kind": kind,
            "layout": layout,
            "obs_dim": obs_dim,
            "reward_model": reward_model,
            "sample_noise_scale": sample_noise_scale,
            "task": task,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        act_dim = d.pop("act_dim")

        action_high = cast(list[float], d.pop("action_high"))


        action_low = cast(list[float], d.pop("action_low"))


        dt = d.pop("dt")

        has_policy = d.pop("has_policy")

        id = d.pop("id")

        kind = ModelKind(d.pop("kind"))




        layout = d.pop("layout")

        obs_dim = d.pop("obs_dim")

        reward_model = d.pop("reward_model")

        sample_noise_scale = d.pop("sample_noise_scale")

        task = d.pop("task")

        model_summary = cls(
            act_dim=act_dim,
            action_high=action_high,
            action_low=action_low,
            dt=dt,
            has_policy=has_policy,
            id=id,
            kind=kind,
            layout=layout,
            obs_dim=obs_dim,
            reward_model=reward_model,
            sample_noise_scale=sample_noise_scale,
            task=task,
        )


        model_summary.additional_properties = d
        return model_summary

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

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.model_kind import ModelKind
from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.model_detail_dataset import ModelDetailDataset
  from ..models.model_detail_hyperparameters import ModelDetailHyperparameters
  from ..models.model_detail_policy import ModelDetailPolicy
  from ..models.model_detail_state_split import ModelDetailStateSplit
  from ..models.model_detail_thresholds import ModelDetailThresholds
  from ..models.model_detail_training import ModelDetailTraining
  from ..models.system_description import SystemDescription





T = TypeVar("T", bound="ModelDetail")



@_attrs_define
class ModelDetail:
    """ Everything about a model.

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
            dataset (ModelDetailDataset):
            hyperparameters (ModelDetailHyperparameters): The model's hyperparameters (the SDE's sizes and diffusion bounds;
                the
                ensemble's members, elites, layers, weight decay).
            policy (ModelDetailPolicy): The policy's provenance (preset, epoch, score), if one is loaded.
            state_split (ModelDetailStateSplit): Observation indices of positions and velocities, and each position's
                velocity (the neural SDE's; null for an ensemble).
            thresholds (ModelDetailThresholds): ε(h, α): `values[i][j]` for `horizons[i]`, `alphas[j]` (null for an
                ensemble).
            training (ModelDetailTraining): Fit summary and configuration (an ensemble's: elites, holdout MSE, epochs).
            system (None | SystemDescription | Unset):
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
    dataset: ModelDetailDataset
    hyperparameters: ModelDetailHyperparameters
    policy: ModelDetailPolicy
    state_split: ModelDetailStateSplit
    thresholds: ModelDetailThresholds
    training: ModelDetailTraining
    system: None | SystemDescription | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.model_detail_dataset import ModelDetailDataset # noqa: PLC0415
        from ..models.model_detail_hyperparameters import ModelDetailHyperparameters # noqa: PLC0415
        from ..models.model_detail_policy import ModelDetailPolicy # noqa: PLC0415
        from ..models.model_detail_state_split import ModelDetailStateSplit # noqa: PLC0415
        from ..models.model_detail_thresholds import ModelDetailThresholds # noqa: PLC0415
        from ..models.model_detail_training import ModelDetailTraining # noqa: PLC0415
        from ..models.system_description import SystemDescription # noqa: PLC0415
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

        dataset = self.dataset.to_dict()

        hyperparameters = self.hyperparameters.to_dict()

        policy = self.policy.to_dict()

        state_split = self.state_split.to_dict()

        thresholds = self.thresholds.to_dict()

        training = self.training.to_dict()

        system: dict[str, Any] | None | Unset
        if isinstance(self.system, Unset):
            system = UNSET
        elif isinstance(self.system, SystemDescription):
            system = self.system.to_dict()
        else:
            system = self.system


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
            "dataset": dataset,
            "hyperparameters": hyperparameters,
            "policy": policy,
            "state_split": state_split,
            "thresholds": thresholds,
            "training": training,
        })
        if system is not UNSET:
            field_dict["system"] = system

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.model_detail_dataset import ModelDetailDataset # noqa: PLC0415
        from ..models.model_detail_hyperparameters import ModelDetailHyperparameters # noqa: PLC0415
        from ..models.model_detail_policy import ModelDetailPolicy # noqa: PLC0415
        from ..models.model_detail_state_split import ModelDetailStateSplit # noqa: PLC0415
        from ..models.model_detail_thresholds import ModelDetailThresholds # noqa: PLC0415
        from ..models.model_detail_training import ModelDetailTraining # noqa: PLC0415
        from ..models.system_description import SystemDescription # noqa: PLC0415
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

        dataset = ModelDetailDataset.from_dict(d.pop("dataset"))




        hyperparameters = ModelDetailHyperparameters.from_dict(d.pop("hyperparameters"))




        policy = ModelDetailPolicy.from_dict(d.pop("policy"))




        state_split = ModelDetailStateSplit.from_dict(d.pop("state_split"))




        thresholds = ModelDetailThresholds.from_dict(d.pop("thresholds"))




        training = ModelDetailTraining.from_dict(d.pop("training"))




        def _parse_system(data: object) -> None | SystemDescription | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                system_type_0 = SystemDescription.from_dict(data)



                return system_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(None | SystemDescription | Unset, data)

        system = _parse_system(d.pop("system", UNSET))


        model_detail = cls(
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
            dataset=dataset,
            hyperparameters=hyperparameters,
            policy=policy,
            state_split=state_split,
            thresholds=thresholds,
            training=training,
            system=system,
        )


        model_detail.additional_properties = d
        return model_detail

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

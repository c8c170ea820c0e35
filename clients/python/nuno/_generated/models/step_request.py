from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="StepRequest")



@_attrs_define
class StepRequest:
    """ A batch of observations and actions to step.

        Attributes:
            actions (list[list[float]]): Actions, `[batch][act_dim]` (act_dim: the model's; as many rows as `states`).
            states (list[list[float]]): Observations, `[batch][obs_dim]` (obs_dim: the model's).
            clip (bool | Unset): Clip actions outside the model's action box into it (default), as
                MuJoCo clips controls; false answers 422 for such an action instead.
            noise_scale (float | None | Unset): Multiplies ε (default: the model's own `sample_noise_scale`, in
                `GET /v1/models/{id}`: 1 samples at the calibrated Σ; a model fitted with
                NUNO's code's convention samples at sqrt(dt); 0 follows the drift).
            particles (int | Unset): Samples per item (default 1). batch × particles is bounded by the
                server's answer budget (`--max-answer-bytes`).
            penalty (float | Unset): λ_pen of the penalised reward r − λ_pen·η (default 1).
            seed (int | Unset): Seed of the noise ε (default 0): the same request gives the same answer.
     """

    actions: list[list[float]]
    states: list[list[float]]
    clip: bool | Unset = UNSET
    noise_scale: float | None | Unset = UNSET
    particles: int | Unset = UNSET
    penalty: float | Unset = UNSET
    seed: int | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        actions = []
        for actions_item_data in self.actions:
            actions_item = actions_item_data


            actions.append(actions_item)



        states = []
        for states_item_data in self.states:
            states_item = states_item_data


            states.append(states_item)



        clip = self.clip

        noise_scale: float | None | Unset
        if isinstance(self.noise_scale, Unset):
            noise_scale = UNSET
        else:
            noise_scale = self.noise_scale

        particles = self.particles

        penalty = self.penalty

        seed = self.seed


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "actions": actions,
            "states": states,
        })
        if clip is not UNSET:
            field_dict["clip"] = clip
        if noise_scale is not UNSET:
            field_dict["noise_scale"] = noise_scale
        if particles is not UNSET:
            field_dict["particles"] = particles
        if penalty is not UNSET:
            field_dict["penalty"] = penalty
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


        states = []
        _states = d.pop("states")
        for states_item_data in (_states):
            states_item = cast(list[float], states_item_data)

            states.append(states_item)


        clip = d.pop("clip", UNSET)

        def _parse_noise_scale(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        noise_scale = _parse_noise_scale(d.pop("noise_scale", UNSET))


        particles = d.pop("particles", UNSET)

        penalty = d.pop("penalty", UNSET)

        seed = d.pop("seed", UNSET)

        step_request = cls(
            actions=actions,
            states=states,
            clip=clip,
            noise_scale=noise_scale,
            particles=particles,
            penalty=penalty,
            seed=seed,
        )

        return step_request


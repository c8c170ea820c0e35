from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast






T = TypeVar("T", bound="StepResponse")



@_attrs_define
class StepResponse:
    """ Per item: the SDE's terms; per item and particle: the sampled step.

        Attributes:
            batch (int):
            clipped_rows (int): Rows whose action was clipped into the action box.
            eta (list[float | None]): Distance-aware uncertainty η(s, a): `[batch]`.
            h_eta (list[list[float | None]]): Epistemic diffusion h(η(s, a)): `[batch][obs_dim]`.
            mean (list[list[float | None]]): s + f(s, a)·dt, the drift mean: `[batch][obs_dim]`.
            model (str):
            next_states (list[list[list[float | None]]]): Sampled next observations: `[batch][particles][obs_dim]`.
            noise_scale (float | None): The scale of ε the samples were drawn at: the request's `noise_scale`,
                else the model's own.
            particles (int):
            penalized_rewards (list[list[float | None]]): r − λ_pen·η: `[batch][particles]`.
            rewards (list[list[float | None]]): The task's reward (or the learned one for NUNO^R): `[batch][particles]`.
            sigma (list[list[float | None]]): Aleatoric diffusion σ(s, a): `[batch][obs_dim]`.
            terminals (list[list[bool]]): The task's termination rule on the next observation: `[batch][particles]`.
     """

    batch: int
    clipped_rows: int
    eta: list[float | None]
    h_eta: list[list[float | None]]
    mean: list[list[float | None]]
    model: str
    next_states: list[list[list[float | None]]]
    noise_scale: float | None
    particles: int
    penalized_rewards: list[list[float | None]]
    rewards: list[list[float | None]]
    sigma: list[list[float | None]]
    terminals: list[list[bool]]
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        batch = self.batch

        clipped_rows = self.clipped_rows

        eta = []
        for eta_item_data in self.eta:
            eta_item: float | None
            eta_item = eta_item_data
            eta.append(eta_item)



        h_eta = []
        for h_eta_item_data in self.h_eta:
            h_eta_item = []
            for h_eta_item_item_data in h_eta_item_data:
                h_eta_item_item: float | None
                h_eta_item_item = h_eta_item_item_data
                h_eta_item.append(h_eta_item_item)


            h_eta.append(h_eta_item)



        mean = []
        for mean_item_data in self.mean:
            mean_item = []
            for mean_item_item_data in mean_item_data:
                mean_item_item: float | None
                mean_item_item = mean_item_item_data
                mean_item.append(mean_item_item)


            mean.append(mean_item)



        model = self.model

        next_states = []
        for next_states_item_data in self.next_states:
            next_states_item = []
            for next_states_item_item_data in next_states_item_data:
                next_states_item_item = []
                for next_states_item_item_item_data in next_states_item_item_data:
                    next_states_item_item_item: float | None
                    next_states_item_item_item = next_states_item_item_item_data
                    next_states_item_item.append(next_states_item_item_item)


                next_states_item.append(next_states_item_item)


            next_states.append(next_states_item)



        noise_scale: float | None
        noise_scale = self.noise_scale

        particles = self.particles

        penalized_rewards = []
        for penalized_rewards_item_data in self.penalized_rewards:
            penalized_rewards_item = []
            for penalized_rewards_item_item_data in penalized_rewards_item_data:
                penalized_rewards_item_item: float | None
                penalized_rewards_item_item = penalized_rewards_item_item_data
                penalized_rewards_item.append(penalized_rewards_item_item)


            penalized_rewards.append(penalized_rewards_item)



        rewards = []
        for rewards_item_data in self.rewards:
            rewards_item = []
            for rewards_item_item_data in rewards_item_data:
                rewards_item_item: float | None
                rewards_item_item = rewards_item_item_data
                rewards_item.append(rewards_item_item)


            rewards.append(rewards_item)



        sigma = []
        for sigma_item_data in self.sigma:
            sigma_item = []
            for sigma_item_item_data in sigma_item_data:
                sigma_item_item: float | None
                sigma_item_item = sigma_item_item_data
                sigma_item.append(sigma_item_item)


            sigma.append(sigma_item)



        terminals = []
        for terminals_item_data in self.terminals:
            terminals_item = terminals_item_data


            terminals.append(terminals_item)




        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "batch": batch,
            "clipped_rows": clipped_rows,
            "eta": eta,
            "h_eta": h_eta,
            "mean": mean,
            "model": model,
            "next_states": next_states,
            "noise_scale": noise_scale,
            "particles": particles,
            "penalized_rewards": penalized_rewards,
            "rewards": rewards,
            "sigma": sigma,
            "terminals": terminals,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        batch = d.pop("batch")

        clipped_rows = d.pop("clipped_rows")

        eta = []
        _eta = d.pop("eta")
        for eta_item_data in (_eta):
            def _parse_eta_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            eta_item = _parse_eta_item(eta_item_data)

            eta.append(eta_item)


        h_eta = []
        _h_eta = d.pop("h_eta")
        for h_eta_item_data in (_h_eta):
            h_eta_item = []
            _h_eta_item = h_eta_item_data
            for h_eta_item_item_data in (_h_eta_item):
                def _parse_h_eta_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                h_eta_item_item = _parse_h_eta_item_item(h_eta_item_item_data)

                h_eta_item.append(h_eta_item_item)

            h_eta.append(h_eta_item)


        mean = []
        _mean = d.pop("mean")
        for mean_item_data in (_mean):
            mean_item = []
            _mean_item = mean_item_data
            for mean_item_item_data in (_mean_item):
                def _parse_mean_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                mean_item_item = _parse_mean_item_item(mean_item_item_data)

                mean_item.append(mean_item_item)

            mean.append(mean_item)


        model = d.pop("model")

        next_states = []
        _next_states = d.pop("next_states")
        for next_states_item_data in (_next_states):
            next_states_item = []
            _next_states_item = next_states_item_data
            for next_states_item_item_data in (_next_states_item):
                next_states_item_item = []
                _next_states_item_item = next_states_item_item_data
                for next_states_item_item_item_data in (_next_states_item_item):
                    def _parse_next_states_item_item_item(data: object) -> float | None:
                        if data is None:
                            return data
                        return cast(float | None, data)

                    next_states_item_item_item = _parse_next_states_item_item_item(next_states_item_item_item_data)

                    next_states_item_item.append(next_states_item_item_item)

                next_states_item.append(next_states_item_item)

            next_states.append(next_states_item)


        def _parse_noise_scale(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        noise_scale = _parse_noise_scale(d.pop("noise_scale"))


        particles = d.pop("particles")

        penalized_rewards = []
        _penalized_rewards = d.pop("penalized_rewards")
        for penalized_rewards_item_data in (_penalized_rewards):
            penalized_rewards_item = []
            _penalized_rewards_item = penalized_rewards_item_data
            for penalized_rewards_item_item_data in (_penalized_rewards_item):
                def _parse_penalized_rewards_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                penalized_rewards_item_item = _parse_penalized_rewards_item_item(penalized_rewards_item_item_data)

                penalized_rewards_item.append(penalized_rewards_item_item)

            penalized_rewards.append(penalized_rewards_item)


        rewards = []
        _rewards = d.pop("rewards")
        for rewards_item_data in (_rewards):
            rewards_item = []
            _rewards_item = rewards_item_data
            for rewards_item_item_data in (_rewards_item):
                def _parse_rewards_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                rewards_item_item = _parse_rewards_item_item(rewards_item_item_data)

                rewards_item.append(rewards_item_item)

            rewards.append(rewards_item)


        sigma = []
        _sigma = d.pop("sigma")
        for sigma_item_data in (_sigma):
            sigma_item = []
            _sigma_item = sigma_item_data
            for sigma_item_item_data in (_sigma_item):
                def _parse_sigma_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                sigma_item_item = _parse_sigma_item_item(sigma_item_item_data)

                sigma_item.append(sigma_item_item)

            sigma.append(sigma_item)


        terminals = []
        _terminals = d.pop("terminals")
        for terminals_item_data in (_terminals):
            terminals_item = cast(list[bool], terminals_item_data)

            terminals.append(terminals_item)


        step_response = cls(
            batch=batch,
            clipped_rows=clipped_rows,
            eta=eta,
            h_eta=h_eta,
            mean=mean,
            model=model,
            next_states=next_states,
            noise_scale=noise_scale,
            particles=particles,
            penalized_rewards=penalized_rewards,
            rewards=rewards,
            sigma=sigma,
            terminals=terminals,
        )


        step_response.additional_properties = d
        return step_response

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

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.action_mode import ActionMode
from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="RolloutRequest")



@_attrs_define
class RolloutRequest:
    """ 
        Attributes:
            horizon (int): Steps h. batch × particles × horizon is bounded by `--max-rollout-steps`
                and the answer budget (`--max-answer-bytes`).
            states (list[list[float]]): Start observations, `[batch][obs_dim]` (obs_dim: the model's).
            actions (list[list[list[float]]] | None | Unset): Open-loop actions `[batch][horizon][act_dim]` (one sequence
                per start
                state, `horizon` steps each, act_dim: the model's); without them the
                model's policy acts (409 when it has none).
            alpha (float | None | Unset): CVaR level α: truncate at the model's ε(h, α) (h = horizon); the pairs
                a model has are in its `thresholds` (`GET /v1/models/{id}`).
            clip (bool | Unset): Clip open-loop actions outside the model's action box into it
                (default), as MuJoCo clips controls; false answers 422 instead.
            noise_scale (float | None | Unset): Multiplies ε (default: the model's own `sample_noise_scale`, in
                `GET /v1/models/{id}`: 1 samples at the calibrated Σ; a model fitted with
                NUNO's code's convention samples at sqrt(dt); 0 follows the drift).
            particles (int | Unset): Trajectories per start state (default 1).
            penalty (float | Unset): λ_pen (default 1).
            policy_mode (ActionMode | Unset): How a trained actor chooses actions.
            seed (int | Unset):
            threshold (float | None | Unset): An explicit truncation threshold instead of α (give one of the two).
     """

    horizon: int
    states: list[list[float]]
    actions: list[list[list[float]]] | None | Unset = UNSET
    alpha: float | None | Unset = UNSET
    clip: bool | Unset = UNSET
    noise_scale: float | None | Unset = UNSET
    particles: int | Unset = UNSET
    penalty: float | Unset = UNSET
    policy_mode: ActionMode | Unset = UNSET
    seed: int | Unset = UNSET
    threshold: float | None | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        horizon = self.horizon

        states = []
        for states_item_data in self.states:
            states_item = states_item_data


            states.append(states_item)



        actions: list[list[list[float]]] | None | Unset
        if isinstance(self.actions, Unset):
            actions = UNSET
        elif isinstance(self.actions, list):
            actions = []
            for actions_type_0_item_data in self.actions:
                actions_type_0_item = []
                for actions_type_0_item_item_data in actions_type_0_item_data:
                    actions_type_0_item_item = actions_type_0_item_item_data


                    actions_type_0_item.append(actions_type_0_item_item)


                actions.append(actions_type_0_item)


        else:
            actions = self.actions

        alpha: float | None | Unset
        if isinstance(self.alpha, Unset):
            alpha = UNSET
        else:
            alpha = self.alpha

        clip = self.clip

        noise_scale: float | None | Unset
        if isinstance(self.noise_scale, Unset):
            noise_scale = UNSET
        else:
            noise_scale = self.noise_scale

        particles = self.particles

        penalty = self.penalty

        policy_mode: str | Unset = UNSET
        if not isinstance(self.policy_mode, Unset):
            policy_mode = self.policy_mode.value


        seed = self.seed

        threshold: float | None | Unset
        if isinstance(self.threshold, Unset):
            threshold = UNSET
        else:
            threshold = self.threshold


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "horizon": horizon,
            "states": states,
        })
        if actions is not UNSET:
            field_dict["actions"] = actions
        if alpha is not UNSET:
            field_dict["alpha"] = alpha
        if clip is not UNSET:
            field_dict["clip"] = clip
        if noise_scale is not UNSET:
            field_dict["noise_scale"] = noise_scale
        if particles is not UNSET:
            field_dict["particles"] = particles
        if penalty is not UNSET:
            field_dict["penalty"] = penalty
        if policy_mode is not UNSET:
            field_dict["policy_mode"] = policy_mode
        if seed is not UNSET:
            field_dict["seed"] = seed
        if threshold is not UNSET:
            field_dict["threshold"] = threshold

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        horizon = d.pop("horizon")

        states = []
        _states = d.pop("states")
        for states_item_data in (_states):
            states_item = cast(list[float], states_item_data)

            states.append(states_item)


        def _parse_actions(data: object) -> list[list[list[float]]] | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, list):
                    raise TypeError()
                actions_type_0 = []
                _actions_type_0 = data
                for actions_type_0_item_data in (_actions_type_0):
                    actions_type_0_item = []
                    _actions_type_0_item = actions_type_0_item_data
                    for actions_type_0_item_item_data in (_actions_type_0_item):
                        actions_type_0_item_item = cast(list[float], actions_type_0_item_item_data)

                        actions_type_0_item.append(actions_type_0_item_item)

                    actions_type_0.append(actions_type_0_item)

                return actions_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(list[list[list[float]]] | None | Unset, data)

        actions = _parse_actions(d.pop("actions", UNSET))


        def _parse_alpha(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        alpha = _parse_alpha(d.pop("alpha", UNSET))


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

        _policy_mode = d.pop("policy_mode", UNSET)
        policy_mode: ActionMode | Unset
        if isinstance(_policy_mode,  Unset):
            policy_mode = UNSET
        else:
            policy_mode = ActionMode(_policy_mode)




        seed = d.pop("seed", UNSET)

        def _parse_threshold(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        threshold = _parse_threshold(d.pop("threshold", UNSET))


        rollout_request = cls(
            horizon=horizon,
            states=states,
            actions=actions,
            alpha=alpha,
            clip=clip,
            noise_scale=noise_scale,
            particles=particles,
            penalty=penalty,
            policy_mode=policy_mode,
            seed=seed,
            threshold=threshold,
        )

        return rollout_request


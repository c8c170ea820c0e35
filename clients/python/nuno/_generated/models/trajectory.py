from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="Trajectory")



@_attrs_define
class Trajectory:
    """ One trajectory; arrays stop where it ended.

        Attributes:
            accumulated_eta (list[float | None]): Σ_{j ≤ k} η(s_j, a_j).
            actions (list[list[float | None]]): The action of every step taken, a truncating one included.
            diverged (bool): The model's next state, reward or η stopped being finite after `length`
                steps (its drift diverged off the data); that step is not kept.
            eta (list[float | None]): η(s_k, a_k) of every step taken.
            length (int): Steps kept.
            particle (int):
            penalized_rewards (list[float | None]): r − λ_pen·η.
            rewards (list[float | None]): Rewards before the penalty.
            start (int): Index of its start state in the request.
            states (list[list[float | None]]): The start, then one observation per kept step: `[length + 1][obs_dim]`.
            terminal (bool): Ended in a terminal state (the task's rules).
            truncated (bool): Accumulated η passed the threshold at step `truncation_step` (that step is not kept).
            truncation_step (int | None | Unset):
     """

    accumulated_eta: list[float | None]
    actions: list[list[float | None]]
    diverged: bool
    eta: list[float | None]
    length: int
    particle: int
    penalized_rewards: list[float | None]
    rewards: list[float | None]
    start: int
    states: list[list[float | None]]
    terminal: bool
    truncated: bool
    truncation_step: int | None | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        accumulated_eta = []
        for accumulated_eta_item_data in self.accumulated_eta:
            accumulated_eta_item: float | None
            accumulated_eta_item = accumulated_eta_item_data
            accumulated_eta.append(accumulated_eta_item)



        actions = []
        for actions_item_data in self.actions:
            actions_item = []
            for actions_item_item_data in actions_item_data:
                actions_item_item: float | None
                actions_item_item = actions_item_item_data
                actions_item.append(actions_item_item)


            actions.append(actions_item)



        diverged = self.diverged

        eta = []
        for eta_item_data in self.eta:
            eta_item: float | None
            eta_item = eta_item_data
            eta.append(eta_item)



        length = self.length

        particle = self.particle

        penalized_rewards = []
        for penalized_rewards_item_data in self.penalized_rewards:
            penalized_rewards_item: float | None
            penalized_rewards_item = penalized_rewards_item_data
            penalized_rewards.append(penalized_rewards_item)



        rewards = []
        for rewards_item_data in self.rewards:
            rewards_item: float | None
            rewards_item = rewards_item_data
            rewards.append(rewards_item)



        start = self.start

        states = []
        for states_item_data in self.states:
            states_item = []
            for states_item_item_data in states_item_data:
                states_item_item: float | None
                states_item_item = states_item_item_data
                states_item.append(states_item_item)


            states.append(states_item)



        terminal = self.terminal

        truncated = self.truncated

        truncation_step: int | None | Unset
        if isinstance(self.truncation_step, Unset):
            truncation_step = UNSET
        else:
            truncation_step = self.truncation_step


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "accumulated_eta": accumulated_eta,
            "actions": actions,
            "diverged": diverged,
            "eta": eta,
            "length": length,
            "particle": particle,
            "penalized_rewards": penalized_rewards,
            "rewards": rewards,
            "start": start,
            "states": states,
            "terminal": terminal,
            "truncated": truncated,
        })
        if truncation_step is not UNSET:
            field_dict["truncation_step"] = truncation_step

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        accumulated_eta = []
        _accumulated_eta = d.pop("accumulated_eta")
        for accumulated_eta_item_data in (_accumulated_eta):
            def _parse_accumulated_eta_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            accumulated_eta_item = _parse_accumulated_eta_item(accumulated_eta_item_data)

            accumulated_eta.append(accumulated_eta_item)


        actions = []
        _actions = d.pop("actions")
        for actions_item_data in (_actions):
            actions_item = []
            _actions_item = actions_item_data
            for actions_item_item_data in (_actions_item):
                def _parse_actions_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                actions_item_item = _parse_actions_item_item(actions_item_item_data)

                actions_item.append(actions_item_item)

            actions.append(actions_item)


        diverged = d.pop("diverged")

        eta = []
        _eta = d.pop("eta")
        for eta_item_data in (_eta):
            def _parse_eta_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            eta_item = _parse_eta_item(eta_item_data)

            eta.append(eta_item)


        length = d.pop("length")

        particle = d.pop("particle")

        penalized_rewards = []
        _penalized_rewards = d.pop("penalized_rewards")
        for penalized_rewards_item_data in (_penalized_rewards):
            def _parse_penalized_rewards_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            penalized_rewards_item = _parse_penalized_rewards_item(penalized_rewards_item_data)

            penalized_rewards.append(penalized_rewards_item)


        rewards = []
        _rewards = d.pop("rewards")
        for rewards_item_data in (_rewards):
            def _parse_rewards_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            rewards_item = _parse_rewards_item(rewards_item_data)

            rewards.append(rewards_item)


        start = d.pop("start")

        states = []
        _states = d.pop("states")
        for states_item_data in (_states):
            states_item = []
            _states_item = states_item_data
            for states_item_item_data in (_states_item):
                def _parse_states_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                states_item_item = _parse_states_item_item(states_item_item_data)

                states_item.append(states_item_item)

            states.append(states_item)


        terminal = d.pop("terminal")

        truncated = d.pop("truncated")

        def _parse_truncation_step(data: object) -> int | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(int | None | Unset, data)

        truncation_step = _parse_truncation_step(d.pop("truncation_step", UNSET))


        trajectory = cls(
            accumulated_eta=accumulated_eta,
            actions=actions,
            diverged=diverged,
            eta=eta,
            length=length,
            particle=particle,
            penalized_rewards=penalized_rewards,
            rewards=rewards,
            start=start,
            states=states,
            terminal=terminal,
            truncated=truncated,
            truncation_step=truncation_step,
        )


        trajectory.additional_properties = d
        return trajectory

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

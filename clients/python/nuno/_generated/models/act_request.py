from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.action_mode import ActionMode
from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="ActRequest")



@_attrs_define
class ActRequest:
    """ 
        Attributes:
            states (list[list[float]]): Observations, `[batch][obs_dim]` (obs_dim: the model's).
            mode (ActionMode | Unset): How a trained actor chooses actions.
            seed (int | Unset): Seed of the policy's noise when sampled.
     """

    states: list[list[float]]
    mode: ActionMode | Unset = UNSET
    seed: int | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        states = []
        for states_item_data in self.states:
            states_item = states_item_data


            states.append(states_item)



        mode: str | Unset = UNSET
        if not isinstance(self.mode, Unset):
            mode = self.mode.value


        seed = self.seed


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "states": states,
        })
        if mode is not UNSET:
            field_dict["mode"] = mode
        if seed is not UNSET:
            field_dict["seed"] = seed

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        states = []
        _states = d.pop("states")
        for states_item_data in (_states):
            states_item = cast(list[float], states_item_data)

            states.append(states_item)


        _mode = d.pop("mode", UNSET)
        mode: ActionMode | Unset
        if isinstance(_mode,  Unset):
            mode = UNSET
        else:
            mode = ActionMode(_mode)




        seed = d.pop("seed", UNSET)

        act_request = cls(
            states=states,
            mode=mode,
            seed=seed,
        )

        return act_request


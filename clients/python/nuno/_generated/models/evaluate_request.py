from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.action_mode import ActionMode
from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="EvaluateRequest")



@_attrs_define
class EvaluateRequest:
    """ 
        Attributes:
            model (str): The model whose policy runs, in the model's task.
            episodes (int | None | Unset): Episodes: 10 by default, or the server's limit when that is lower;
                episode i resets with seed + i (mod 2⁶⁴).
            mode (ActionMode | Unset): How a trained actor chooses actions.
            seed (int | Unset):
     """

    model: str
    episodes: int | None | Unset = UNSET
    mode: ActionMode | Unset = UNSET
    seed: int | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        model = self.model

        episodes: int | None | Unset
        if isinstance(self.episodes, Unset):
            episodes = UNSET
        else:
            episodes = self.episodes

        mode: str | Unset = UNSET
        if not isinstance(self.mode, Unset):
            mode = self.mode.value


        seed = self.seed


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "model": model,
        })
        if episodes is not UNSET:
            field_dict["episodes"] = episodes
        if mode is not UNSET:
            field_dict["mode"] = mode
        if seed is not UNSET:
            field_dict["seed"] = seed

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        model = d.pop("model")

        def _parse_episodes(data: object) -> int | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(int | None | Unset, data)

        episodes = _parse_episodes(d.pop("episodes", UNSET))


        _mode = d.pop("mode", UNSET)
        mode: ActionMode | Unset
        if isinstance(_mode,  Unset):
            mode = UNSET
        else:
            mode = ActionMode(_mode)




        seed = d.pop("seed", UNSET)

        evaluate_request = cls(
            model=model,
            episodes=episodes,
            mode=mode,
            seed=seed,
        )

        return evaluate_request


from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast






T = TypeVar("T", bound="ActResponse")



@_attrs_define
class ActResponse:
    """ 
        Attributes:
            actions (list[list[float | None]]): `[batch][act_dim]`, inside the task's action box.
            model (str):
     """

    actions: list[list[float | None]]
    model: str
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        actions = []
        for actions_item_data in self.actions:
            actions_item = []
            for actions_item_item_data in actions_item_data:
                actions_item_item: float | None
                actions_item_item = actions_item_item_data
                actions_item.append(actions_item_item)


            actions.append(actions_item)



        model = self.model


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "actions": actions,
            "model": model,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
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


        model = d.pop("model")

        act_response = cls(
            actions=actions,
            model=model,
        )


        act_response.additional_properties = d
        return act_response

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

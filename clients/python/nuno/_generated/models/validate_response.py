from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast






T = TypeVar("T", bound="ValidateResponse")



@_attrs_define
class ValidateResponse:
    """ 
        Attributes:
            model (str):
            model_states (list[list[float | None]]): The model's (particle-mean) observations, `[steps + 1][obs_dim]`.
            normalized_rmse (list[float | None]): The same with each entry divided by the dataset's std.
            real_states (list[list[float | None]]): Real observations, `[steps + 1][obs_dim]`.
            rmse (list[float | None]): RMSE over observation entries after each step, physical units: `[steps]`.
            steps (int): Steps compared: until the horizon, or until the real task or the model terminated.
     """

    model: str
    model_states: list[list[float | None]]
    normalized_rmse: list[float | None]
    real_states: list[list[float | None]]
    rmse: list[float | None]
    steps: int
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        model = self.model

        model_states = []
        for model_states_item_data in self.model_states:
            model_states_item = []
            for model_states_item_item_data in model_states_item_data:
                model_states_item_item: float | None
                model_states_item_item = model_states_item_item_data
                model_states_item.append(model_states_item_item)


            model_states.append(model_states_item)



        normalized_rmse = []
        for normalized_rmse_item_data in self.normalized_rmse:
            normalized_rmse_item: float | None
            normalized_rmse_item = normalized_rmse_item_data
            normalized_rmse.append(normalized_rmse_item)



        real_states = []
        for real_states_item_data in self.real_states:
            real_states_item = []
            for real_states_item_item_data in real_states_item_data:
                real_states_item_item: float | None
                real_states_item_item = real_states_item_item_data
                real_states_item.append(real_states_item_item)


            real_states.append(real_states_item)



        rmse = []
        for rmse_item_data in self.rmse:
            rmse_item: float | None
            rmse_item = rmse_item_data
            rmse.append(rmse_item)



        steps = self.steps


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "model": model,
            "model_states": model_states,
            "normalized_rmse": normalized_rmse,
            "real_states": real_states,
            "rmse": rmse,
            "steps": steps,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        model = d.pop("model")

        model_states = []
        _model_states = d.pop("model_states")
        for model_states_item_data in (_model_states):
            model_states_item = []
            _model_states_item = model_states_item_data
            for model_states_item_item_data in (_model_states_item):
                def _parse_model_states_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                model_states_item_item = _parse_model_states_item_item(model_states_item_item_data)

                model_states_item.append(model_states_item_item)

            model_states.append(model_states_item)


        normalized_rmse = []
        _normalized_rmse = d.pop("normalized_rmse")
        for normalized_rmse_item_data in (_normalized_rmse):
            def _parse_normalized_rmse_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            normalized_rmse_item = _parse_normalized_rmse_item(normalized_rmse_item_data)

            normalized_rmse.append(normalized_rmse_item)


        real_states = []
        _real_states = d.pop("real_states")
        for real_states_item_data in (_real_states):
            real_states_item = []
            _real_states_item = real_states_item_data
            for real_states_item_item_data in (_real_states_item):
                def _parse_real_states_item_item(data: object) -> float | None:
                    if data is None:
                        return data
                    return cast(float | None, data)

                real_states_item_item = _parse_real_states_item_item(real_states_item_item_data)

                real_states_item.append(real_states_item_item)

            real_states.append(real_states_item)


        rmse = []
        _rmse = d.pop("rmse")
        for rmse_item_data in (_rmse):
            def _parse_rmse_item(data: object) -> float | None:
                if data is None:
                    return data
                return cast(float | None, data)

            rmse_item = _parse_rmse_item(rmse_item_data)

            rmse.append(rmse_item)


        steps = d.pop("steps")

        validate_response = cls(
            model=model,
            model_states=model_states,
            normalized_rmse=normalized_rmse,
            real_states=real_states,
            rmse=rmse,
            steps=steps,
        )


        validate_response.additional_properties = d
        return validate_response

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

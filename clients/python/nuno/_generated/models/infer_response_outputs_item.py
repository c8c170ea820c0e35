from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.infer_response_outputs_item_parameters_type_0 import InferResponseOutputsItemParametersType0





T = TypeVar("T", bound="InferResponseOutputsItem")



@_attrs_define
class InferResponseOutputsItem:
    """ One v2 tensor: its data inline (`data`, flattened row-major), or with the
    binary tensor extension `parameters.binary_data_size` bytes after the JSON
    header.

        Attributes:
            datatype (str):
            name (str):
            shape (list[int]):
            data (list[bool | float | None] | Unset):
            parameters (InferResponseOutputsItemParametersType0 | None | Unset):
     """

    datatype: str
    name: str
    shape: list[int]
    data: list[bool | float | None] | Unset = UNSET
    parameters: InferResponseOutputsItemParametersType0 | None | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.infer_response_outputs_item_parameters_type_0 import InferResponseOutputsItemParametersType0 # noqa: PLC0415
        datatype = self.datatype

        name = self.name

        shape = self.shape



        data: list[bool | float | None] | Unset = UNSET
        if not isinstance(self.data, Unset):
            data = []
            for data_item_data in self.data:
                data_item: bool | float | None
                data_item = data_item_data
                data.append(data_item)



        parameters: dict[str, Any] | None | Unset
        if isinstance(self.parameters, Unset):
            parameters = UNSET
        elif isinstance(self.parameters, InferResponseOutputsItemParametersType0):
            parameters = self.parameters.to_dict()
        else:
            parameters = self.parameters


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "datatype": datatype,
            "name": name,
            "shape": shape,
        })
        if data is not UNSET:
            field_dict["data"] = data
        if parameters is not UNSET:
            field_dict["parameters"] = parameters

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.infer_response_outputs_item_parameters_type_0 import InferResponseOutputsItemParametersType0 # noqa: PLC0415
        d = dict(src_dict)
        datatype = d.pop("datatype")

        name = d.pop("name")

        shape = cast(list[int], d.pop("shape"))


        _data = d.pop("data", UNSET)
        data: list[bool | float | None] | Unset = UNSET
        if _data is not UNSET:
            data = []
            for data_item_data in _data:
                def _parse_data_item(data: object) -> bool | float | None:
                    if data is None:
                        return data
                    return cast(bool | float | None, data)

                data_item = _parse_data_item(data_item_data)

                data.append(data_item)


        def _parse_parameters(data: object) -> InferResponseOutputsItemParametersType0 | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                parameters_type_0 = InferResponseOutputsItemParametersType0.from_dict(data)



                return parameters_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(InferResponseOutputsItemParametersType0 | None | Unset, data)

        parameters = _parse_parameters(d.pop("parameters", UNSET))


        infer_response_outputs_item = cls(
            datatype=datatype,
            name=name,
            shape=shape,
            data=data,
            parameters=parameters,
        )


        infer_response_outputs_item.additional_properties = d
        return infer_response_outputs_item

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

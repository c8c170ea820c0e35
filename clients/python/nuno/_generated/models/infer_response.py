from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.infer_response_outputs_item import InferResponseOutputsItem
  from ..models.infer_response_parameters import InferResponseParameters





T = TypeVar("T", bound="InferResponse")



@_attrs_define
class InferResponse:
    """ 
        Attributes:
            model_name (str):
            model_version (str):
            outputs (list[InferResponseOutputsItem]):
            parameters (InferResponseParameters): `clipped_rows`: rows whose action was clipped into the model's action box.
            id (None | str | Unset):
     """

    model_name: str
    model_version: str
    outputs: list[InferResponseOutputsItem]
    parameters: InferResponseParameters
    id: None | str | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.infer_response_outputs_item import InferResponseOutputsItem # noqa: PLC0415
        from ..models.infer_response_parameters import InferResponseParameters # noqa: PLC0415
        model_name = self.model_name

        model_version = self.model_version

        outputs = []
        for outputs_item_data in self.outputs:
            outputs_item = outputs_item_data.to_dict()
            outputs.append(outputs_item)



        parameters = self.parameters.to_dict()

        id: None | str | Unset
        if isinstance(self.id, Unset):
            id = UNSET
        else:
            id = self.id


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "model_name": model_name,
            "model_version": model_version,
            "outputs": outputs,
            "parameters": parameters,
        })
        if id is not UNSET:
            field_dict["id"] = id

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.infer_response_outputs_item import InferResponseOutputsItem # noqa: PLC0415
        from ..models.infer_response_parameters import InferResponseParameters # noqa: PLC0415
        d = dict(src_dict)
        model_name = d.pop("model_name")

        model_version = d.pop("model_version")

        outputs = []
        _outputs = d.pop("outputs")
        for outputs_item_data in (_outputs):
            outputs_item = InferResponseOutputsItem.from_dict(outputs_item_data)



            outputs.append(outputs_item)


        parameters = InferResponseParameters.from_dict(d.pop("parameters"))




        def _parse_id(data: object) -> None | str | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(None | str | Unset, data)

        id = _parse_id(d.pop("id", UNSET))


        infer_response = cls(
            model_name=model_name,
            model_version=model_version,
            outputs=outputs,
            parameters=parameters,
            id=id,
        )


        infer_response.additional_properties = d
        return infer_response

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

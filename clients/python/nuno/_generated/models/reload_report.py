from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
  from ..models.load_failure import LoadFailure





T = TypeVar("T", bound="ReloadReport")



@_attrs_define
class ReloadReport:
    """ What a (re)load did.

        Attributes:
            failed (list[LoadFailure]): Models that failed; a previous version, if any, is still served.
            loaded (list[str]): Ids served after the reload.
     """

    failed: list[LoadFailure]
    loaded: list[str]
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.load_failure import LoadFailure # noqa: PLC0415
        failed = []
        for failed_item_data in self.failed:
            failed_item = failed_item_data.to_dict()
            failed.append(failed_item)



        loaded = self.loaded




        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "failed": failed,
            "loaded": loaded,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.load_failure import LoadFailure # noqa: PLC0415
        d = dict(src_dict)
        failed = []
        _failed = d.pop("failed")
        for failed_item_data in (_failed):
            failed_item = LoadFailure.from_dict(failed_item_data)



            failed.append(failed_item)


        loaded = cast(list[str], d.pop("loaded"))


        reload_report = cls(
            failed=failed,
            loaded=loaded,
        )


        reload_report.additional_properties = d
        return reload_report

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

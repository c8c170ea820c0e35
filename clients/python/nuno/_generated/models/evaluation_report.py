from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast






T = TypeVar("T", bound="EvaluationReport")



@_attrs_define
class EvaluationReport:
    """ Per-episode results and their summary.

        Attributes:
            lengths (list[int]):
            mean_normalized_score (float):
            mean_return (float):
            normalized_scores (list[float]):
            returns (list[float]):
            std_normalized_score (float):
            std_return (float):
     """

    lengths: list[int]
    mean_normalized_score: float
    mean_return: float
    normalized_scores: list[float]
    returns: list[float]
    std_normalized_score: float
    std_return: float
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        lengths = self.lengths



        mean_normalized_score = self.mean_normalized_score

        mean_return = self.mean_return

        normalized_scores = self.normalized_scores



        returns = self.returns



        std_normalized_score = self.std_normalized_score

        std_return = self.std_return


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "lengths": lengths,
            "mean_normalized_score": mean_normalized_score,
            "mean_return": mean_return,
            "normalized_scores": normalized_scores,
            "returns": returns,
            "std_normalized_score": std_normalized_score,
            "std_return": std_return,
        })

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        lengths = cast(list[int], d.pop("lengths"))


        mean_normalized_score = d.pop("mean_normalized_score")

        mean_return = d.pop("mean_return")

        normalized_scores = cast(list[float], d.pop("normalized_scores"))


        returns = cast(list[float], d.pop("returns"))


        std_normalized_score = d.pop("std_normalized_score")

        std_return = d.pop("std_return")

        evaluation_report = cls(
            lengths=lengths,
            mean_normalized_score=mean_normalized_score,
            mean_return=mean_return,
            normalized_scores=normalized_scores,
            returns=returns,
            std_normalized_score=std_normalized_score,
            std_return=std_return,
        )


        evaluation_report.additional_properties = d
        return evaluation_report

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

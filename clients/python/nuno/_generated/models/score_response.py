from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.candidate_score import CandidateScore





T = TypeVar("T", bound="ScoreResponse")



@_attrs_define
class ScoreResponse:
    """ 
        Attributes:
            batch (int):
            candidates (int):
            clipped_rows (int): Action rows (candidate × step) clipped into the action box.
            horizon (int):
            model (str):
            noise_scale (float): The scale of ε the samples were drawn at.
            particles (int):
            scores (list[list[CandidateScore]]): `[batch][candidates]`.
            threshold (float | None | Unset): The truncation threshold used, if any.
     """

    batch: int
    candidates: int
    clipped_rows: int
    horizon: int
    model: str
    noise_scale: float
    particles: int
    scores: list[list[CandidateScore]]
    threshold: float | None | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.candidate_score import CandidateScore # noqa: PLC0415
        batch = self.batch

        candidates = self.candidates

        clipped_rows = self.clipped_rows

        horizon = self.horizon

        model = self.model

        noise_scale = self.noise_scale

        particles = self.particles

        scores = []
        for scores_item_data in self.scores:
            scores_item = []
            for scores_item_item_data in scores_item_data:
                scores_item_item = scores_item_item_data.to_dict()
                scores_item.append(scores_item_item)


            scores.append(scores_item)



        threshold: float | None | Unset
        if isinstance(self.threshold, Unset):
            threshold = UNSET
        else:
            threshold = self.threshold


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "batch": batch,
            "candidates": candidates,
            "clipped_rows": clipped_rows,
            "horizon": horizon,
            "model": model,
            "noise_scale": noise_scale,
            "particles": particles,
            "scores": scores,
        })
        if threshold is not UNSET:
            field_dict["threshold"] = threshold

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.candidate_score import CandidateScore # noqa: PLC0415
        d = dict(src_dict)
        batch = d.pop("batch")

        candidates = d.pop("candidates")

        clipped_rows = d.pop("clipped_rows")

        horizon = d.pop("horizon")

        model = d.pop("model")

        noise_scale = d.pop("noise_scale")

        particles = d.pop("particles")

        scores = []
        _scores = d.pop("scores")
        for scores_item_data in (_scores):
            scores_item = []
            _scores_item = scores_item_data
            for scores_item_item_data in (_scores_item):
                scores_item_item = CandidateScore.from_dict(scores_item_item_data)



                scores_item.append(scores_item_item)

            scores.append(scores_item)


        def _parse_threshold(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        threshold = _parse_threshold(d.pop("threshold", UNSET))


        score_response = cls(
            batch=batch,
            candidates=candidates,
            clipped_rows=clipped_rows,
            horizon=horizon,
            model=model,
            noise_scale=noise_scale,
            particles=particles,
            scores=scores,
            threshold=threshold,
        )


        score_response.additional_properties = d
        return score_response

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

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast






T = TypeVar("T", bound="CandidateScore")



@_attrs_define
class CandidateScore:
    """ One candidate's score, over its particles.

        Attributes:
            accumulated_eta (float | None): Mean over particles of Σ η_t along the steps kept.
            diverged (float | None): The share of particles whose model state stopped being finite.
            max_eta (float | None): The largest η any particle met at a step it took.
            mean_return (float | None): Mean over particles of Σ γ^t r_t.
            penalized_return (float | None): Mean over particles of Σ γ^t (r_t − λ·η_t).
            terminated (float | None): The share of particles whose task rules ended them (the robot fell).
            cvar_return (float | None | Unset): Mean of the worst ⌈α·P⌉ particles' returns, when α was asked for.
            truncated_at (int | None | Unset): The first step (0-based) at which a particle's accumulated η passed
                ε(H, α) and the step was dropped; `None` if none did.
     """

    accumulated_eta: float | None
    diverged: float | None
    max_eta: float | None
    mean_return: float | None
    penalized_return: float | None
    terminated: float | None
    cvar_return: float | None | Unset = UNSET
    truncated_at: int | None | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        accumulated_eta: float | None
        accumulated_eta = self.accumulated_eta

        diverged: float | None
        diverged = self.diverged

        max_eta: float | None
        max_eta = self.max_eta

        mean_return: float | None
        mean_return = self.mean_return

        penalized_return: float | None
        penalized_return = self.penalized_return

        terminated: float | None
        terminated = self.terminated

        cvar_return: float | None | Unset
        if isinstance(self.cvar_return, Unset):
            cvar_return = UNSET
        else:
            cvar_return = self.cvar_return

        truncated_at: int | None | Unset
        if isinstance(self.truncated_at, Unset):
            truncated_at = UNSET
        else:
            truncated_at = self.truncated_at


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "accumulated_eta": accumulated_eta,
            "diverged": diverged,
            "max_eta": max_eta,
            "mean_return": mean_return,
            "penalized_return": penalized_return,
            "terminated": terminated,
        })
        if cvar_return is not UNSET:
            field_dict["cvar_return"] = cvar_return
        if truncated_at is not UNSET:
            field_dict["truncated_at"] = truncated_at

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        def _parse_accumulated_eta(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        accumulated_eta = _parse_accumulated_eta(d.pop("accumulated_eta"))


        def _parse_diverged(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        diverged = _parse_diverged(d.pop("diverged"))


        def _parse_max_eta(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        max_eta = _parse_max_eta(d.pop("max_eta"))


        def _parse_mean_return(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        mean_return = _parse_mean_return(d.pop("mean_return"))


        def _parse_penalized_return(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        penalized_return = _parse_penalized_return(d.pop("penalized_return"))


        def _parse_terminated(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        terminated = _parse_terminated(d.pop("terminated"))


        def _parse_cvar_return(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        cvar_return = _parse_cvar_return(d.pop("cvar_return", UNSET))


        def _parse_truncated_at(data: object) -> int | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(int | None | Unset, data)

        truncated_at = _parse_truncated_at(d.pop("truncated_at", UNSET))


        candidate_score = cls(
            accumulated_eta=accumulated_eta,
            diverged=diverged,
            max_eta=max_eta,
            mean_return=mean_return,
            penalized_return=penalized_return,
            terminated=terminated,
            cvar_return=cvar_return,
            truncated_at=truncated_at,
        )


        candidate_score.additional_properties = d
        return candidate_score

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

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.cost_term_request import CostTermRequest





T = TypeVar("T", bound="CostRequest")



@_attrs_define
class CostRequest:
    """ A request's quadratic costs on the observations its candidates reach.

        Attributes:
            terms (list[CostTermRequest]): Each kept step's reward becomes r − Σ weight·(s′[observation] − target)².
            replace_reward (bool | Unset): Score on the costs alone: −Σ weight·(s′ − target)², the model's reward left out.
     """

    terms: list[CostTermRequest]
    replace_reward: bool | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        from ..models.cost_term_request import CostTermRequest # noqa: PLC0415
        terms = []
        for terms_item_data in self.terms:
            terms_item = terms_item_data.to_dict()
            terms.append(terms_item)



        replace_reward = self.replace_reward


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "terms": terms,
        })
        if replace_reward is not UNSET:
            field_dict["replace_reward"] = replace_reward

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.cost_term_request import CostTermRequest # noqa: PLC0415
        d = dict(src_dict)
        terms = []
        _terms = d.pop("terms")
        for terms_item_data in (_terms):
            terms_item = CostTermRequest.from_dict(terms_item_data)



            terms.append(terms_item)


        replace_reward = d.pop("replace_reward", UNSET)

        cost_request = cls(
            terms=terms,
            replace_reward=replace_reward,
        )

        return cost_request


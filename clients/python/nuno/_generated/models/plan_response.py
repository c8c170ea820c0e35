from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.planner import Planner
from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
  from ..models.candidate_score import CandidateScore





T = TypeVar("T", bound="PlanResponse")



@_attrs_define
class PlanResponse:
    """ 
        Attributes:
            actions (list[list[float]]): `[horizon][act_dim]`: the plan; its first row is the action to take now.
            first_action (list[float]):
            model (str):
            objective (float): What the planner maximised, for the plan.
            planner (Planner): The planners, by name: the server's `planner`, the trainer's `--planner`.
            score (CandidateScore): One candidate's score, over its particles.
            seconds (float): Seconds the planning took, queueing for a compute slot excluded.
            warm_started (bool): Whether the search started from the session's last plan.
            session (None | str | Unset): The session that keeps this plan, if any.
     """

    actions: list[list[float]]
    first_action: list[float]
    model: str
    objective: float
    planner: Planner
    score: CandidateScore
    seconds: float
    warm_started: bool
    session: None | str | Unset = UNSET
    additional_properties: dict[str, Any] = _attrs_field(init=False, factory=dict)





    def to_dict(self) -> dict[str, Any]:
        from ..models.candidate_score import CandidateScore # noqa: PLC0415
        actions = []
        for actions_item_data in self.actions:
            actions_item = actions_item_data


            actions.append(actions_item)



        first_action = self.first_action



        model = self.model

        objective = self.objective

        planner = self.planner.value

        score = self.score.to_dict()

        seconds = self.seconds

        warm_started = self.warm_started

        session: None | str | Unset
        if isinstance(self.session, Unset):
            session = UNSET
        else:
            session = self.session


        field_dict: dict[str, Any] = {}
        field_dict.update(self.additional_properties)
        field_dict.update({
            "actions": actions,
            "first_action": first_action,
            "model": model,
            "objective": objective,
            "planner": planner,
            "score": score,
            "seconds": seconds,
            "warm_started": warm_started,
        })
        if session is not UNSET:
            field_dict["session"] = session

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.candidate_score import CandidateScore # noqa: PLC0415
        d = dict(src_dict)
        actions = []
        _actions = d.pop("actions")
        for actions_item_data in (_actions):
            actions_item = cast(list[float], actions_item_data)

            actions.append(actions_item)


        first_action = cast(list[float], d.pop("first_action"))


        model = d.pop("model")

        objective = d.pop("objective")

        planner = Planner(d.pop("planner"))




        score = CandidateScore.from_dict(d.pop("score"))




        seconds = d.pop("seconds")

        warm_started = d.pop("warm_started")

        def _parse_session(data: object) -> None | str | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(None | str | Unset, data)

        session = _parse_session(d.pop("session", UNSET))


        plan_response = cls(
            actions=actions,
            first_action=first_action,
            model=model,
            objective=objective,
            planner=planner,
            score=score,
            seconds=seconds,
            warm_started=warm_started,
            session=session,
        )


        plan_response.additional_properties = d
        return plan_response

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

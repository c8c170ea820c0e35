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
  from ..models.cost_request import CostRequest





T = TypeVar("T", bound="PlanRequest")



@_attrs_define
class PlanRequest:
    """ 
        Attributes:
            horizon (int): Steps H of the plan.
            iterations (int):
            planner (Planner): The planners, by name: the server's `planner`, the trainer's `--planner`.
            population (int): Candidates sampled per iteration.
            state (list[float]): The state to plan from, `[obs_dim]` (the model's).
            alpha (float | None | Unset): CVaR level α of the truncation ε(H, α); or give `threshold`.
            colored_noise (float | None | Unset): iCEM: the exponent β of the samples' power spectrum f^(−β) along
                time (default 2: smooth; 0: white, as CEM).
            cost (CostRequest | None | Unset):
            cvar_alpha (float | None | Unset): Risk: maximise the CVaR of the return over this share of particles,
                worst first, less λ·(mean accumulated η).
            decay (float | None | Unset): iCEM: iteration i samples ⌈population·decay^(−i)⌉, at least 2·elites (default
                1.3).
            discount (float | Unset): γ of the returns (default 1).
            elites (int | None | Unset): CEM and iCEM: the candidates each iteration refits to (default
                ⌈population / 10⌉; at most the population, which more elites mean).
            keep_elites (float | None | Unset): iCEM: the share of elites carried to the next iteration and, with a
                session, the next call (default 0.3).
            momentum (float | None | Unset): CEM and iCEM: the share of the old distribution kept per refit (default 0.1).
            noise (float | None | Unset): Sampling spread as a share of each action's half-range (default: CEM and iCEM 0.5,
                MPPI 1).
            noise_scale (float | None | Unset): Multiplies ε (default: the model's own `sample_noise_scale`).
            open_session (bool | Unset): Open a session, named in the answer, that keeps this plan.
            particles (int | Unset): Samples of each candidate (default 1).
            penalty (float | Unset): λ on η: candidates maximise Σ γ^t (r_t − λ·η_t) (default 1).
            seed (int | Unset):
            session (None | str | Unset): Continue this session: warm-start from its last plan, shifted one step.
            smoothing (float | None | Unset): MPPI: β of the smoothed noise (default 0.9, mbrl-lib's).
            temperature (float | None | Unset): MPPI: weights exp((R − max R)/temperature) (default 1).
            threshold (float | None | Unset):
     """

    horizon: int
    iterations: int
    planner: Planner
    population: int
    state: list[float]
    alpha: float | None | Unset = UNSET
    colored_noise: float | None | Unset = UNSET
    cost: CostRequest | None | Unset = UNSET
    cvar_alpha: float | None | Unset = UNSET
    decay: float | None | Unset = UNSET
    discount: float | Unset = UNSET
    elites: int | None | Unset = UNSET
    keep_elites: float | None | Unset = UNSET
    momentum: float | None | Unset = UNSET
    noise: float | None | Unset = UNSET
    noise_scale: float | None | Unset = UNSET
    open_session: bool | Unset = UNSET
    particles: int | Unset = UNSET
    penalty: float | Unset = UNSET
    seed: int | Unset = UNSET
    session: None | str | Unset = UNSET
    smoothing: float | None | Unset = UNSET
    temperature: float | None | Unset = UNSET
    threshold: float | None | Unset = UNSET





    def to_dict(self) -> dict[str, Any]:
        from ..models.cost_request import CostRequest # noqa: PLC0415
        horizon = self.horizon

        iterations = self.iterations

        planner = self.planner.value

        population = self.population

        state = self.state



        alpha: float | None | Unset
        if isinstance(self.alpha, Unset):
            alpha = UNSET
        else:
            alpha = self.alpha

        colored_noise: float | None | Unset
        if isinstance(self.colored_noise, Unset):
            colored_noise = UNSET
        else:
            colored_noise = self.colored_noise

        cost: dict[str, Any] | None | Unset
        if isinstance(self.cost, Unset):
            cost = UNSET
        elif isinstance(self.cost, CostRequest):
            cost = self.cost.to_dict()
        else:
            cost = self.cost

        cvar_alpha: float | None | Unset
        if isinstance(self.cvar_alpha, Unset):
            cvar_alpha = UNSET
        else:
            cvar_alpha = self.cvar_alpha

        decay: float | None | Unset
        if isinstance(self.decay, Unset):
            decay = UNSET
        else:
            decay = self.decay

        discount = self.discount

        elites: int | None | Unset
        if isinstance(self.elites, Unset):
            elites = UNSET
        else:
            elites = self.elites

        keep_elites: float | None | Unset
        if isinstance(self.keep_elites, Unset):
            keep_elites = UNSET
        else:
            keep_elites = self.keep_elites

        momentum: float | None | Unset
        if isinstance(self.momentum, Unset):
            momentum = UNSET
        else:
            momentum = self.momentum

        noise: float | None | Unset
        if isinstance(self.noise, Unset):
            noise = UNSET
        else:
            noise = self.noise

        noise_scale: float | None | Unset
        if isinstance(self.noise_scale, Unset):
            noise_scale = UNSET
        else:
            noise_scale = self.noise_scale

        open_session = self.open_session

        particles = self.particles

        penalty = self.penalty

        seed = self.seed

        session: None | str | Unset
        if isinstance(self.session, Unset):
            session = UNSET
        else:
            session = self.session

        smoothing: float | None | Unset
        if isinstance(self.smoothing, Unset):
            smoothing = UNSET
        else:
            smoothing = self.smoothing

        temperature: float | None | Unset
        if isinstance(self.temperature, Unset):
            temperature = UNSET
        else:
            temperature = self.temperature

        threshold: float | None | Unset
        if isinstance(self.threshold, Unset):
            threshold = UNSET
        else:
            threshold = self.threshold


        field_dict: dict[str, Any] = {}

        field_dict.update({
            "horizon": horizon,
            "iterations": iterations,
            "planner": planner,
            "population": population,
            "state": state,
        })
        if alpha is not UNSET:
            field_dict["alpha"] = alpha
        if colored_noise is not UNSET:
            field_dict["colored_noise"] = colored_noise
        if cost is not UNSET:
            field_dict["cost"] = cost
        if cvar_alpha is not UNSET:
            field_dict["cvar_alpha"] = cvar_alpha
        if decay is not UNSET:
            field_dict["decay"] = decay
        if discount is not UNSET:
            field_dict["discount"] = discount
        if elites is not UNSET:
            field_dict["elites"] = elites
        if keep_elites is not UNSET:
            field_dict["keep_elites"] = keep_elites
        if momentum is not UNSET:
            field_dict["momentum"] = momentum
        if noise is not UNSET:
            field_dict["noise"] = noise
        if noise_scale is not UNSET:
            field_dict["noise_scale"] = noise_scale
        if open_session is not UNSET:
            field_dict["open_session"] = open_session
        if particles is not UNSET:
            field_dict["particles"] = particles
        if penalty is not UNSET:
            field_dict["penalty"] = penalty
        if seed is not UNSET:
            field_dict["seed"] = seed
        if session is not UNSET:
            field_dict["session"] = session
        if smoothing is not UNSET:
            field_dict["smoothing"] = smoothing
        if temperature is not UNSET:
            field_dict["temperature"] = temperature
        if threshold is not UNSET:
            field_dict["threshold"] = threshold

        return field_dict



    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.cost_request import CostRequest # noqa: PLC0415
        d = dict(src_dict)
        horizon = d.pop("horizon")

        iterations = d.pop("iterations")

        planner = Planner(d.pop("planner"))




        population = d.pop("population")

        state = cast(list[float], d.pop("state"))


        def _parse_alpha(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        alpha = _parse_alpha(d.pop("alpha", UNSET))


        def _parse_colored_noise(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        colored_noise = _parse_colored_noise(d.pop("colored_noise", UNSET))


        def _parse_cost(data: object) -> CostRequest | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                cost_type_0 = CostRequest.from_dict(data)



                return cost_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(CostRequest | None | Unset, data)

        cost = _parse_cost(d.pop("cost", UNSET))


        def _parse_cvar_alpha(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        cvar_alpha = _parse_cvar_alpha(d.pop("cvar_alpha", UNSET))


        def _parse_decay(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        decay = _parse_decay(d.pop("decay", UNSET))


        discount = d.pop("discount", UNSET)

        def _parse_elites(data: object) -> int | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(int | None | Unset, data)

        elites = _parse_elites(d.pop("elites", UNSET))


        def _parse_keep_elites(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        keep_elites = _parse_keep_elites(d.pop("keep_elites", UNSET))


        def _parse_momentum(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        momentum = _parse_momentum(d.pop("momentum", UNSET))


        def _parse_noise(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        noise = _parse_noise(d.pop("noise", UNSET))


        def _parse_noise_scale(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        noise_scale = _parse_noise_scale(d.pop("noise_scale", UNSET))


        open_session = d.pop("open_session", UNSET)

        particles = d.pop("particles", UNSET)

        penalty = d.pop("penalty", UNSET)

        seed = d.pop("seed", UNSET)

        def _parse_session(data: object) -> None | str | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(None | str | Unset, data)

        session = _parse_session(d.pop("session", UNSET))


        def _parse_smoothing(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        smoothing = _parse_smoothing(d.pop("smoothing", UNSET))


        def _parse_temperature(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        temperature = _parse_temperature(d.pop("temperature", UNSET))


        def _parse_threshold(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        threshold = _parse_threshold(d.pop("threshold", UNSET))


        plan_request = cls(
            horizon=horizon,
            iterations=iterations,
            planner=planner,
            population=population,
            state=state,
            alpha=alpha,
            colored_noise=colored_noise,
            cost=cost,
            cvar_alpha=cvar_alpha,
            decay=decay,
            discount=discount,
            elites=elites,
            keep_elites=keep_elites,
            momentum=momentum,
            noise=noise,
            noise_scale=noise_scale,
            open_session=open_session,
            particles=particles,
            penalty=penalty,
            seed=seed,
            session=session,
            smoothing=smoothing,
            temperature=temperature,
            threshold=threshold,
        )

        return plan_request


"""The hand layer over the generated client: numpy arrays in and out, binary
(safetensors) bodies for large batches, and one exception for every error
the server answers."""
from __future__ import annotations

import json
from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any

import httpx
import numpy as np
from numpy.typing import ArrayLike, NDArray
from safetensors.numpy import load as load_tensors
from safetensors.numpy import save as save_tensors

from ._generated import AuthenticatedClient
from ._generated import Client as GeneratedClient
from ._generated.api.evaluation import evaluate as evaluate_route
from ._generated.api.models import act as act_route
from ._generated.api.models import get_model, list_models
from ._generated.models import (
    ActRequest,
    ActionMode,
    ErrorBody,
    EvaluateRequest,
    EvaluateResponse,
    ModelDetail,
    ModelSummary,
    PlanResponse,
    RolloutRequest,
)
from ._generated.types import UNSET
from .errors import NunoError

BINARY = "application/octet-stream"
# A step's float arrays, by their name on the wire and in `Step`.
_STEP_ARRAYS = ("mean", "sigma", "h_eta", "eta", "next_states", "rewards", "penalized_rewards")

Array = NDArray[np.float32]


@dataclass(frozen=True)
class Step:
    """One sampled step of a batch: per item the model's terms, per item and
    particle the samples (`next_states[b, p]`)."""

    mean: Array
    sigma: Array
    h_eta: Array
    eta: Array
    next_states: Array
    rewards: Array
    penalized_rewards: Array
    terminals: NDArray[np.bool_]
    noise_scale: float
    clipped_rows: int


@dataclass(frozen=True)
class Scores:
    """Each candidate's score, `[batch, candidates]`: returns (mean, penalised,
    CVaR over particles), η (accumulated, largest), the share of particles that
    terminated or diverged, and the step truncation cut it at (-1: never)."""

    mean_return: Array
    penalized_return: Array
    cvar_return: Array
    accumulated_eta: Array
    max_eta: Array
    terminated: Array
    diverged: Array
    truncated_at: NDArray[np.int64]
    noise_scale: float
    clipped_rows: int


@dataclass(frozen=True)
class Rollout:
    """Trajectories `[starts, particles, ...]`, NaN past each one's `length`
    steps; `outcome` 0 ran to the horizon, 1 terminal, 2 truncated, 3 diverged."""

    states: Array
    actions: Array
    eta: Array
    accumulated_eta: Array
    rewards: Array
    penalized_rewards: Array
    length: NDArray[np.int64]
    outcome: NDArray[np.int64]
    noise_scale: float
    clipped_rows: int


def _matrix(values: ArrayLike, name: str) -> Array:
    array = np.ascontiguousarray(values, dtype=np.float32)
    if array.ndim == 1:
        array = array[None, :]
    if array.ndim != 2:
        raise ValueError(f"`{name}` must be [batch, width], got shape {array.shape}")
    return array


class Client:
    """A nuno model server at `base_url` (`http://127.0.0.1:8080`), with its
    bearer `token` if it was started with one.

    Batches of at least `binary_rows` rows (rows × particles for `step`) travel
    as safetensors bytes, smaller ones as JSON; `binary=True/False` on a call
    overrides it.
    """

    def __init__(
        self,
        base_url: str,
        token: str | None = None,
        timeout: float = 120.0,
        binary_rows: int = 4096,
    ) -> None:
        timeout_config = httpx.Timeout(timeout)
        if token is None:
            self.generated: GeneratedClient | AuthenticatedClient = GeneratedClient(
                base_url=base_url, timeout=timeout_config
            )
        else:
            self.generated = AuthenticatedClient(
                base_url=base_url, token=token, timeout=timeout_config
            )
        self.binary_rows = binary_rows

    @property
    def _http(self) -> httpx.Client:
        return self.generated.get_httpx_client()

    def models(self) -> list[ModelSummary]:
        """Every model the server holds."""
        return _parsed(list_models.sync_detailed(client=self.generated)).models

    def model(self, model: str) -> ModelDetail:
        """One model's widths, action box, kind, thresholds and provenance."""
        return _parsed(get_model.sync_detailed(model, client=self.generated))

    def step(
        self,
        model: str,
        states: ArrayLike,
        actions: ArrayLike,
        *,
        particles: int = 1,
        seed: int = 0,
        penalty: float = 1.0,
        noise_scale: float | None = None,
        clip: bool = True,
        binary: bool | None = None,
    ) -> Step:
        """One Euler–Maruyama step of every (state, action) row, `particles` samples each."""
        s, a = _matrix(states, "states"), _matrix(actions, "actions")
        options: dict[str, Any] = {
            "particles": particles,
            "seed": seed,
            "penalty": penalty,
            "clip": clip,
        }
        if noise_scale is not None:
            options["noise_scale"] = noise_scale
        if binary is None:
            binary = len(s) * particles >= self.binary_rows
        path = f"/v1/models/{model}/step"
        if binary:
            metadata = {k: str(v).lower() if isinstance(v, bool) else str(v) for k, v in options.items()}
            body = save_tensors({"states": s, "actions": a}, metadata=metadata)
            answer = self._post(path, content=body, headers={"content-type": BINARY})
            tensors, meta = _tensors(answer)
            return _step(tensors, meta)
        answer = self._post(path, json={"states": s.tolist(), "actions": a.tolist(), **options}).json()
        return _step(answer, answer)

    def rollout(
        self,
        model: str,
        states: ArrayLike,
        horizon: int,
        *,
        actions: ArrayLike | None = None,
        particles: int = 1,
        seed: int = 0,
        penalty: float = 1.0,
        alpha: float | None = None,
        threshold: float | None = None,
        noise_scale: float | None = None,
        policy_mode: str = "sampled",
        clip: bool = True,
    ) -> Rollout:
        """`horizon` steps from every start state, by the model's policy or the
        open-loop `actions` `[starts, horizon, act_dim]`; truncated where the
        accumulated η passes ε(horizon, alpha) or `threshold`. The answer
        travels as safetensors whatever its size."""
        s = _matrix(states, "states")
        request = RolloutRequest(
            horizon=horizon,
            states=s.tolist(),
            actions=UNSET if actions is None else np.asarray(actions, dtype=np.float32).tolist(),
            particles=particles,
            seed=seed,
            penalty=penalty,
            alpha=UNSET if alpha is None else alpha,
            threshold=UNSET if threshold is None else threshold,
            noise_scale=UNSET if noise_scale is None else noise_scale,
            policy_mode=ActionMode(policy_mode),
            clip=clip,
        )
        answer = self._post(
            f"/v1/models/{model}/rollout", json=request.to_dict(), headers={"accept": BINARY}
        )
        tensors, meta = _tensors(answer)
        starts = len(s)

        def shaped(name: str) -> Array:
            value = tensors[name]
            return value.reshape((starts, particles) + value.shape[1:])

        return Rollout(
            states=shaped("states"),
            actions=shaped("actions"),
            eta=shaped("eta"),
            accumulated_eta=shaped("accumulated_eta"),
            rewards=shaped("rewards"),
            penalized_rewards=shaped("penalized_rewards"),
            length=shaped("length").astype(np.int64),
            outcome=shaped("outcome").astype(np.int64),
            noise_scale=float(meta["noise_scale"]),
            clipped_rows=int(meta["clipped_rows"]),
        )

    def score(
        self,
        model: str,
        states: ArrayLike,
        actions: ArrayLike,
        *,
        particles: int = 1,
        seed: int = 0,
        **options: Any,
    ) -> Scores:
        """Scores candidate action sequences `actions` `[batch, candidates,
        horizon, act_dim]` from each start state in the model; `options` are
        the route's own (`discount`, `cvar_alpha`, `penalty`, `threshold`,
        `alpha`, `cost`, `noise_scale`, `clip`)."""
        s = _matrix(states, "states")
        candidates = np.asarray(actions, dtype=np.float32)
        if candidates.ndim != 4:
            raise ValueError(
                f"`actions` must be [batch, candidates, horizon, act_dim], got shape {candidates.shape}"
            )
        request = {
            "states": s.tolist(),
            "actions": candidates.tolist(),
            "horizon": candidates.shape[2],
            "particles": particles,
            "seed": seed,
            **options,
        }
        answer = self._post(f"/v1/models/{model}/score", json=request).json()
        rows = answer["scores"]

        def field(name: str, missing: float = np.nan) -> Array:
            return np.asarray(
                [[missing if c.get(name) is None else c[name] for c in row] for row in rows],
                dtype=np.float32,
            )

        return Scores(
            mean_return=field("mean_return"),
            penalized_return=field("penalized_return"),
            cvar_return=field("cvar_return"),
            accumulated_eta=field("accumulated_eta"),
            max_eta=field("max_eta"),
            terminated=field("terminated"),
            diverged=field("diverged"),
            truncated_at=field("truncated_at", -1).astype(np.int64),
            noise_scale=float(answer["noise_scale"]),
            clipped_rows=int(answer["clipped_rows"]),
        )

    def plan(
        self,
        model: str,
        state: ArrayLike,
        *,
        planner: str = "cem",
        horizon: int = 10,
        population: int = 64,
        iterations: int = 3,
        **options: Any,
    ) -> PlanResponse:
        """One plan from `state` by `planner` (cem, icem, mppi) in the model:
        its action sequence, first action, score and objective; `options` are
        the route's own (`particles`, `seed`, `session`, `open_session`, ...)."""
        request = {
            "state": np.asarray(state, dtype=np.float32).reshape(-1).tolist(),
            "planner": planner,
            "horizon": horizon,
            "population": population,
            "iterations": iterations,
            **options,
        }
        answer = self._post(f"/v1/models/{model}/plan", json=request).json()
        return PlanResponse.from_dict(answer)

    def act(self, model: str, states: ArrayLike, *, mode: str = "deterministic", seed: int = 0) -> Array:
        """The model's policy's actions `[batch, act_dim]`."""
        request = ActRequest(states=_matrix(states, "states").tolist(), mode=ActionMode(mode), seed=seed)
        answer = _parsed(act_route.sync_detailed(model, client=self.generated, body=request))
        return np.asarray(answer.actions, dtype=np.float32)

    def evaluate(
        self, model: str, episodes: int = 10, *, mode: str = "deterministic", seed: int = 0
    ) -> EvaluateResponse:
        """The model's policy in the real MuJoCo task: returns and normalised scores."""
        request = EvaluateRequest(model=model, episodes=episodes, mode=ActionMode(mode), seed=seed)
        return _parsed(evaluate_route.sync_detailed(client=self.generated, body=request))

    def _post(self, path: str, **kwargs: Any) -> httpx.Response:
        answer = self._http.post(path, **kwargs)
        if answer.status_code >= 400:
            raise _error(answer.status_code, answer.content)
        return answer


def _step(arrays: Mapping[str, Any], scalars: Mapping[str, Any]) -> Step:
    """A step's answer from its arrays (safetensors tensors or JSON lists) and
    its scalars (the safetensors metadata or the JSON body)."""
    f32 = {name: np.asarray(arrays[name], dtype=np.float32) for name in _STEP_ARRAYS}
    return Step(
        **f32,
        terminals=np.asarray(arrays["terminals"]) != 0,
        noise_scale=float(scalars["noise_scale"]),
        clipped_rows=int(scalars["clipped_rows"]),
    )


def _tensors(answer: httpx.Response) -> tuple[dict[str, Array], dict[str, str]]:
    """A safetensors answer's tensors and header metadata."""
    content = answer.content
    header_length = int.from_bytes(content[:8], "little")
    metadata = json.loads(content[8 : 8 + header_length]).get("__metadata__", {})
    return load_tensors(content), metadata


def _error(status: int, content: bytes) -> NunoError:
    """The server's `{"error": {"code", "message"}}` as a `NunoError`."""
    try:
        error = json.loads(content)["error"]
        return NunoError(status, str(error.get("code", "unknown")), str(error.get("message", "")))
    except (ValueError, KeyError, TypeError):
        return NunoError(status, "unknown", content.decode("utf-8", "replace")[:500])


def _parsed(response: Any) -> Any:
    """A generated call's parsed answer, or its error raised."""
    parsed = response.parsed
    if int(response.status_code) >= 400 or isinstance(parsed, ErrorBody) or parsed is None:
        raise _error(int(response.status_code), response.content)
    return parsed

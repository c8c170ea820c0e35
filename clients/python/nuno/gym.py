"""A served model as the environment RL code already speaks to: `ModelEnv` is a
`gymnasium.Env` whose every step is one sampled step of the model on the server."""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .client import Client


class ModelEnv(gymnasium.Env[NDArray[np.float32], NDArray[np.float32]]):
    """The model `model` on `client`'s server as an environment.

    - spaces: observations `Box(-inf, inf, (obs_dim,))`, actions the model's action box;
    - `reset` starts from `options["state"]` when given, else from a row of
      `start_states` drawn with the env's generator (dataset states, typically);
    - `step` samples the model's next state (one particle, its noise seeded from
      the env's generator, so a seeded episode repeats), rewards it with the
      penalised reward r − `penalty`·η (or the task's reward with
      `penalized=False`), `terminated` from the model's termination rule,
      `truncated` at `max_episode_steps` or once the accumulated η passes
      `eta_budget` (ε(h, α) from `GET /v1/models/{id}`'s table, say), and reports η,
      σ, h(η) and the accumulated η in `info`.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        client: Client,
        model: str,
        *,
        start_states: ArrayLike | None = None,
        max_episode_steps: int = 1000,
        penalty: float = 1.0,
        penalized: bool = True,
        eta_budget: float | None = None,
        noise_scale: float | None = None,
    ) -> None:
        detail = client.model(model)
        self.client, self.model = client, model
        self.observation_space = gymnasium.spaces.Box(
            -np.inf, np.inf, shape=(detail.obs_dim,), dtype=np.float32
        )
        self.action_space = gymnasium.spaces.Box(
            np.asarray(detail.action_low, dtype=np.float32),
            np.asarray(detail.action_high, dtype=np.float32),
            dtype=np.float32,
        )
        self.start_states = (
            None if start_states is None else np.asarray(start_states, dtype=np.float32)
        )
        if self.start_states is not None and self.start_states.shape[1:] != (detail.obs_dim,):
            raise ValueError(
                f"start_states must be [n, {detail.obs_dim}], got {self.start_states.shape}"
            )
        self.max_episode_steps = max_episode_steps
        self.penalty, self.penalized = penalty, penalized
        self.eta_budget, self.noise_scale = eta_budget, noise_scale
        self._state: NDArray[np.float32] | None = None
        self._steps, self._accumulated_eta = 0, 0.0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        if options is not None and "state" in options:
            state = np.asarray(options["state"], dtype=np.float32)
        elif self.start_states is not None and len(self.start_states) > 0:
            state = self.start_states[self.np_random.integers(len(self.start_states))]
        else:
            raise ValueError("reset needs options={'state': ...} or the env's start_states")
        if state.shape != self.observation_space.shape:
            raise ValueError(f"a start state must be {self.observation_space.shape}, got {state.shape}")
        self._state = state.copy()
        self._steps, self._accumulated_eta = 0, 0.0
        return self._state.copy(), {}

    def step(
        self, action: ArrayLike
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        if self._state is None:
            raise RuntimeError("call reset before step")
        action = np.asarray(action, dtype=np.float32).reshape(self.action_space.shape)
        sample = self.client.step(
            self.model,
            self._state[None, :],
            action[None, :],
            particles=1,
            seed=int(self.np_random.integers(2**63)),
            penalty=self.penalty,
            noise_scale=self.noise_scale,
            binary=False,
        )
        self._state = sample.next_states[0, 0].astype(np.float32)
        eta = float(sample.eta[0])
        self._steps += 1
        self._accumulated_eta += eta
        rewards = sample.penalized_rewards if self.penalized else sample.rewards
        terminated = bool(sample.terminals[0, 0])
        over_budget = self.eta_budget is not None and self._accumulated_eta > self.eta_budget
        truncated = not terminated and (self._steps >= self.max_episode_steps or over_budget)
        info = {
            "eta": eta,
            "accumulated_eta": self._accumulated_eta,
            "sigma": sample.sigma[0],
            "h_eta": sample.h_eta[0],
            "reward": float(sample.rewards[0, 0]),
        }
        return self._state.copy(), float(rewards[0, 0]), terminated, truncated, info

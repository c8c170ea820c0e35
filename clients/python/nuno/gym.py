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


class ModelVectorEnv(gymnasium.vector.VectorEnv):
    """`num_envs` copies of [`ModelEnv`] stepped together: each `step` is one
    request to the server with a row per environment (one particle each), so
    a vectorised RL loop pays one round trip per step, not one per environment.

    Spaces, rewards, η-budget truncation and `info` are `ModelEnv`'s, batched
    (`info` holds arrays, one entry per environment). Environments that end
    are reset on the next `step` (Gymnasium's NEXT_STEP autoreset: that step
    returns the new start state with reward 0 and neither flag set, ignoring
    its action). `reset(options={"state": [num_envs, obs_dim]})` starts from
    given states, else from rows of `start_states` drawn with the env's generator.
    """

    metadata: dict[str, Any] = {"render_modes": [], "autoreset_mode": gymnasium.vector.AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        client: Client,
        model: str,
        num_envs: int,
        *,
        start_states: ArrayLike | None = None,
        max_episode_steps: int = 1000,
        penalty: float = 1.0,
        penalized: bool = True,
        eta_budget: float | None = None,
        noise_scale: float | None = None,
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        single = ModelEnv(client, model, start_states=start_states)
        self.client, self.model, self.num_envs = client, model, num_envs
        self.single_observation_space = single.observation_space
        self.single_action_space = single.action_space
        self.observation_space = gymnasium.vector.utils.batch_space(single.observation_space, num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(single.action_space, num_envs)
        self.start_states = single.start_states
        self.max_episode_steps = max_episode_steps
        self.penalty, self.penalized = penalty, penalized
        self.eta_budget, self.noise_scale = eta_budget, noise_scale
        self._states: NDArray[np.float32] | None = None
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._accumulated_eta = np.zeros(num_envs)
        self._ended = np.zeros(num_envs, dtype=bool)

    def _starts(self, count: int) -> NDArray[np.float32]:
        if self.start_states is None or len(self.start_states) == 0:
            raise ValueError("reset needs options={'state': ...} or the env's start_states")
        return self.start_states[self.np_random.integers(len(self.start_states), size=count)].copy()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        if seed is not None:
            self._np_random, self._np_random_seed = gymnasium.utils.seeding.np_random(seed)
        if options is not None and "state" in options:
            states = np.asarray(options["state"], dtype=np.float32)
        else:
            states = self._starts(self.num_envs)
        if states.shape != self.observation_space.shape:
            raise ValueError(f"start states must be {self.observation_space.shape}, got {states.shape}")
        self._states = states.copy()
        self._steps[:] = 0
        self._accumulated_eta[:] = 0.0
        self._ended[:] = False
        return self._states.copy(), {}

    def step(self, actions: ArrayLike):
        if self._states is None:
            raise RuntimeError("call reset before step")
        actions = np.asarray(actions, dtype=np.float32).reshape(self.action_space.shape)
        sample = self.client.step(
            self.model,
            self._states,
            actions,
            particles=1,
            seed=int(self.np_random.integers(2**63)),
            penalty=self.penalty,
            noise_scale=self.noise_scale,
        )
        eta = np.asarray(sample.eta, dtype=np.float64)
        rewards = (sample.penalized_rewards if self.penalized else sample.rewards)[:, 0].astype(np.float64)
        terminated = np.asarray(sample.terminals[:, 0], dtype=bool)
        states = sample.next_states[:, 0].astype(np.float32)
        self._steps += 1
        self._accumulated_eta += eta
        over_budget = (
            self._accumulated_eta > self.eta_budget if self.eta_budget is not None else np.zeros(self.num_envs, bool)
        )
        truncated = ~terminated & ((self._steps >= self.max_episode_steps) | over_budget)
        # NEXT_STEP autoreset: the environments that ended last step start over
        # now; their row of this step (their old state, the ignored action) is dropped.
        restart = self._ended
        if restart.any():
            states[restart] = self._starts(int(restart.sum()))
            rewards[restart] = eta[restart] = 0.0
            terminated[restart] = truncated[restart] = False
            self._steps[restart] = 0
            self._accumulated_eta[restart] = 0.0
        info = {
            "eta": eta,
            "accumulated_eta": self._accumulated_eta.copy(),
            "sigma": np.asarray(sample.sigma),
            "h_eta": np.asarray(sample.h_eta),
            "reward": np.where(restart, 0.0, sample.rewards[:, 0].astype(np.float64)),
        }
        self._ended = terminated | truncated
        self._states = states
        return states.copy(), rewards, terminated, truncated, info

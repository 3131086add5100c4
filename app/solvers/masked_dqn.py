"""Stable-Baselines3 DQN that never picks a cap-breaking robot. Imports torch: load lazily.

SB3's DQN has no action masking. The allowed robots lead every observation of
`AllocationEnv`, so masking lives in three small overrides:

- the Q-network sets disallowed robots to a very low value, which masks the greedy action
  and also the max in the TD target (the target network is the same class), so values of
  robots that can never be chosen do not leak into the bootstrap;
- epsilon-exploration and the warm-up phase sample uniformly among allowed robots, using
  the action space's seeded generator as SB3 itself does;
- nothing else: replay, target updates and optimisation are SB3's own.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork

MASKED_Q = -1e6


def silent_logger() -> Logger:
    """A logger with no outputs and no folder. SB3's default (`configure`) makes an empty
    tempdir/SB3-<time> directory on every `learn`, even with verbose=0."""
    return Logger(folder=None, output_formats=[])


class MaskedQNetwork(QNetwork):
    def forward(self, obs: Any) -> th.Tensor:
        q_values = super().forward(obs)
        allowed = obs[:, : q_values.shape[1]] > 0.5
        return q_values.masked_fill(~allowed, MASKED_Q)


class MaskedDQNPolicy(DQNPolicy):
    def make_q_net(self) -> QNetwork:
        net_args = self._update_features_extractor(self.net_args, features_extractor=None)
        return MaskedQNetwork(**net_args).to(self.device)


class MaskedDQN(DQN):
    def _random_allowed(self, observation: np.ndarray) -> np.ndarray:
        space = self.action_space
        assert isinstance(space, spaces.Discrete)  # one robot per action (AllocationEnv)
        n = int(space.n)
        rows = np.asarray(observation).reshape(-1, np.asarray(observation).shape[-1])
        return np.array([space.sample(mask=(row[:n] > 0.5).astype(np.int8)) for row in rows])

    def predict(
        self,
        observation: Any,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        if not deterministic and np.random.rand() < self.exploration_rate:
            actions = self._random_allowed(observation)
            single = not self.policy.is_vectorized_observation(observation)
            return (actions[0] if single else actions), state
        return self.policy.predict(observation, state, episode_start, deterministic)

    def _sample_action(
        self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        if self.num_timesteps < learning_starts:
            # AllocationEnv's observations are one Box, never a dict of them.
            assert isinstance(self._last_obs, np.ndarray)
            action = self._random_allowed(self._last_obs)
        else:
            action, _ = self.predict(self._last_obs, deterministic=False)
        return action, action


def q_values(model: DQN, observation: np.ndarray) -> np.ndarray:
    """The online network's Q-values for one observation."""
    obs = th.as_tensor(observation, dtype=th.float32, device=model.device).unsqueeze(0)
    with th.no_grad():
        return model.q_net(obs).squeeze(0).cpu().numpy()

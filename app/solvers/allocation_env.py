"""The allocation queue as a Gymnasium environment, for the DQN solver.

One episode walks the queue in order; the action is the robot for the current task. Only
robots that keep the workload cap satisfiable (`WorkloadCap.feasible_robots`) are allowed;
`action_masks()` lists them and they also lead the observation, so a Q-network can mask
itself. Stepping with a disallowed robot is a caller bug and raises.

Reward: the *expected* success S[t, robot] minus the best S any robot has on task t (minus
the regret), not a sampled outcome. Every episode visits the same tasks, so the subtracted
part sums to the same constant in every episode: with gamma = 1 the optimal policy is
unchanged, while the values to learn stay small and centred on 0 at every step instead of
growing with the number of tasks left.

Observation (float32, each block one entry per robot unless noted):
allowed (0/1) | S on this task | S minus the task's best S | final-load shortfall
(tasks still owed to reach the cap's lower bound) / tasks left | remaining room to the
upper bound / tasks left (clipped to 1) | share of the later tasks on which the robot
is (jointly) best | mean regret of the robot over the later tasks | progress t / n (one).
The last two let the network see what the rest of the queue offers each robot.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from app.domain.cap import WorkloadCap

_TIE = 1e-9
BLOCKS = 7  # per-robot blocks before the progress entry


class AllocationEnv(gym.Env[np.ndarray, np.int64]):
    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 - gymnasium's own shape

    def __init__(
        self,
        success: np.ndarray,
        cap: WorkloadCap,
        initial_loads: Sequence[int] | None = None,
        feasible: Callable[[int, Sequence[int]], list[int]] | None = None,
    ) -> None:
        """`success` and `cap` over the tasks and robots to decide (a FreePart's); every
        episode starts from `initial_loads` (the pins' loads), zeros by default. `feasible`
        (task, loads) -> robots replaces the cap's count where eligibility restricts
        (`FreePart.feasible_robots`, docs/allocation.md#teams)."""
        super().__init__()
        self.success = np.asarray(success, dtype=float)
        self.cap = cap
        self._lower, self._upper = cap.lower, cap.upper  # exact-fraction properties: cache
        self.n_tasks, self.n_robots = self.success.shape
        self.action_space = gym.spaces.Discrete(self.n_robots)
        size = BLOCKS * self.n_robots + 1
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(size,), dtype=np.float32)
        regret = self.success - self.success.max(axis=1, keepdims=True)
        self._regret = regret
        self._later_best, self._later_regret = _later_summaries(regret)
        self._start = list(initial_loads) if initial_loads is not None else [0] * self.n_robots
        if len(self._start) != self.n_robots:
            raise ValueError(f"{len(self._start)} initial loads for {self.n_robots} robots")
        self._t = 0
        self._loads = list(self._start)
        self._masks: dict[tuple[int, ...], np.ndarray] = {}
        self._feasible = feasible

    @property
    def loads(self) -> list[int]:
        return list(self._loads)

    def action_masks(self) -> np.ndarray:
        # Training revisits the same load vectors thousands of times; the cap check is exact
        # (fractions) and slow, so remember it per load vector (which also fixes t).
        key = tuple(self._loads)
        mask = self._masks.get(key)
        if mask is None:
            mask = np.zeros(self.n_robots, dtype=bool)
            if self._t < self.n_tasks and self._feasible is not None:
                mask[self._feasible(self._t, self._loads)] = True
            elif self._t < self.n_tasks:
                mask[self.cap.feasible_robots(self._loads, self.n_tasks - self._t - 1)] = True
            self._masks[key] = mask
        return mask.copy()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._t = 0
        self._loads = list(self._start)
        return self._observation(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        robot = int(action)
        if not self.action_masks()[robot]:
            raise ValueError(
                f"robot {robot} for task {self._t} would break the workload cap; "
                "act only on action_masks()"
            )
        reward = float(self._regret[self._t, robot])
        self._loads[robot] += 1
        self._t += 1
        done = self._t == self.n_tasks
        return self._observation(), reward, done, False, {}

    def _observation(self) -> np.ndarray:
        r, t = self.n_robots, self._t
        obs = np.zeros(BLOCKS * r + 1, dtype=np.float32)
        obs[-1] = t / self.n_tasks
        if t == self.n_tasks:
            # No decision is made here; all-allowed keeps a masked max finite.
            obs[:r] = 1.0
            return obs
        left = self.n_tasks - t
        loads = np.asarray(self._loads, dtype=float)
        obs[0:r] = self.action_masks()
        obs[r : 2 * r] = self.success[t]
        obs[2 * r : 3 * r] = self._regret[t]
        obs[3 * r : 4 * r] = np.maximum(0.0, self._lower - loads) / left
        obs[4 * r : 5 * r] = np.minimum(1.0, (self._upper - loads) / left)
        obs[5 * r : 6 * r] = self._later_best[t]
        obs[6 * r : 7 * r] = self._later_regret[t]
        return obs


def _later_summaries(regret: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per task t: share of tasks after t where each robot is best, and its mean regret there."""
    n, r = regret.shape
    best = (regret >= -_TIE).astype(float)
    # Suffix sums from t+1 on; the row for the last task sees no later tasks (zeros).
    best_after = np.vstack([np.cumsum(best[::-1], axis=0)[::-1][1:], np.zeros((1, r))])
    regret_after = np.vstack([np.cumsum(regret[::-1], axis=0)[::-1][1:], np.zeros((1, r))])
    later = np.maximum(1, n - 1 - np.arange(n))[:, None]
    return best_after / later, regret_after / later

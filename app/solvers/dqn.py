"""Deep Q-Network: Stable-Baselines3 DQN trained on `AllocationEnv`, approximate and seeded.

Rewards are expected success (S minus the task's best S; see `allocation_env`), not
sampled outcomes: a network needs far fewer transitions to learn from a noise-free signal,
and the optimum is the same. Cap-breaking robots are masked in exploration, in the TD
target and when the trained policy acts (argmax of the Q-values over allowed robots), so
the allocation always respects the cap.

torch, SB3 and gymnasium are the optional `rl` extra: they are imported only when a DQN
solve runs, so importing this module or listing solvers never loads torch.

Reproducibility: training runs on one torch thread with SB3, torch, numpy and the action
space seeded from `seed`, so the same seed gives the same allocation. Seeding SB3 touches
process-wide generators (random, numpy, torch) and the torch thread count; they are
restored afterwards, and a lock keeps two concurrent solves from interleaving on them.
"""

from __future__ import annotations

import random
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Annotated, Any

import numpy as np
from pydantic import Field, model_validator

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo, SolverOptions
from app.solvers.free_part import FreePart

INSTALL_HINT = "install the rl extra: pip install torch==2.13.0 && pip install -e '.[rl]'"

# Process-wide RNG and thread state are only safe to borrow one training at a time.
_TRAINING_LOCK = threading.Lock()


class DQNOptions(SolverOptions):
    # Bounded so one request cannot hold the (serialised) trainer for long: 200,000 steps
    # is about 5 minutes here; train_freq and target_update_interval above `timesteps`
    # would make SB3 collect forever without training.
    timesteps: int = Field(20_000, ge=100, le=200_000, description="environment steps of training")
    learning_rate: float = Field(1e-3, gt=0.0, le=1.0)
    gamma: float = Field(1.0, ge=0.0, le=1.0, description="discount; 1 suits the fixed horizon")
    batch_size: int = Field(64, ge=1, le=4096)
    buffer_size: int = Field(50_000, ge=100, le=1_000_000)
    learning_starts: int = Field(
        1_000,
        ge=0,
        le=200_000,
        description="random steps before training; at most a tenth of timesteps",
    )
    target_update_interval: int = Field(500, ge=1, le=200_000, description="at most timesteps")
    train_freq: int = Field(4, ge=1, le=1_000, description="at most timesteps")
    exploration_fraction: float = Field(0.5, gt=0.0, le=1.0)
    exploration_final_eps: float = Field(0.05, ge=0.0, le=1.0)
    net_arch: list[Annotated[int, Field(ge=1, le=1024)]] = Field(
        default_factory=lambda: [128, 128],
        min_length=1,
        max_length=4,
        description="hidden layer widths of the Q-network",
    )

    @model_validator(mode="after")
    def _within_timesteps(self) -> DQNOptions:
        for name in ("train_freq", "target_update_interval"):
            if name in self.model_fields_set and getattr(self, name) > self.timesteps:
                raise ValueError(
                    f"{name} ({getattr(self, name)}) must not exceed timesteps ({self.timesteps})"
                )
        return self


def _import_rl() -> tuple[ModuleType, ModuleType, ModuleType]:
    try:
        import torch

        from app.solvers import allocation_env, masked_dqn
    except ImportError as exc:
        missing = exc.name or str(exc)
        raise DomainError(
            "solver",
            f"dqn needs torch, stable-baselines3 and gymnasium ({missing} is "
            f"missing); {INSTALL_HINT}",
            code="solver_unavailable",
        ) from None
    return torch, allocation_env, masked_dqn


@contextmanager
def _borrowed_global_state(torch: ModuleType) -> Iterator[None]:
    with _TRAINING_LOCK:
        threads = torch.get_num_threads()
        saved = random.getstate(), np.random.get_state(), torch.get_rng_state()
        torch.set_num_threads(1)
        try:
            yield
        finally:
            torch.set_num_threads(threads)
            random.setstate(saved[0])
            np.random.set_state(saved[1])
            torch.set_rng_state(saved[2])


class DQNSolver(Solver):
    info = SolverInfo(
        name="dqn",
        description="Deep Q-Network (Stable-Baselines3 DQN, PyTorch) over a Gymnasium "
        "allocation environment with cap-breaking robots masked; approximate (not "
        "guaranteed optimal), seeded and reproducible. Needs the rl extra.",
        exact=False,
        limits="any size within the request limits; training time grows with timesteps",
    )
    Options = DQNOptions

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        opts: DQNOptions = options
        torch, allocation_env, masked_dqn = _import_rl()
        # Trained on the pinned problem: the free tasks, the available robots, the pins' loads.
        part = FreePart.of(problem)
        if part.n_tasks == 0:  # everything is pinned: nothing to learn or decide
            return Solution(part.assignment([]), details={"timesteps": 0})
        success = part.success

        def environment() -> Any:
            feasible = None if part.eligible.all() else part.feasible_robots
            return allocation_env.AllocationEnv(success, part.cap, part.initial_loads, feasible)

        with _borrowed_global_state(torch):
            env = environment()
            model = masked_dqn.MaskedDQN(
                masked_dqn.MaskedDQNPolicy,
                env,
                learning_rate=opts.learning_rate,
                gamma=opts.gamma,
                batch_size=opts.batch_size,
                buffer_size=min(opts.buffer_size, opts.timesteps),
                learning_starts=min(opts.learning_starts, opts.timesteps // 10),
                target_update_interval=opts.target_update_interval,
                train_freq=opts.train_freq,
                exploration_fraction=opts.exploration_fraction,
                exploration_final_eps=opts.exploration_final_eps,
                policy_kwargs={"net_arch": list(opts.net_arch)},
                seed=seed,
                device="cpu",
                verbose=0,
            )
            model.set_logger(masked_dqn.silent_logger())
            model.learn(total_timesteps=opts.timesteps)
            choices = _act(model, environment(), masked_dqn.q_values)
        return Solution(part.assignment(choices), details={"timesteps": opts.timesteps})


def _act(model: Any, env: Any, q_values: Any) -> list[int]:
    """Greedy rollout: argmax of the Q-values over the robots the cap still allows."""
    obs, _ = env.reset()
    assignment: list[int] = []
    done = False
    while not done:
        allowed = env.action_masks()
        q = np.where(allowed, q_values(model, obs), -np.inf)
        robot = int(np.argmax(q))
        assignment.append(robot)
        obs, _, done, _, _ = env.step(robot)
    return assignment

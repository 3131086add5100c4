"""Tabular Q-learning over (task index, load vector): an approximate, seeded RL baseline.

An episode walks the whole queue; the action is the robot for the current task and the
reward is a Bernoulli draw with probability S[t, robot] (the task succeeded or not), so
the agent learns from sampled outcomes, never from S directly. Undiscounted (gamma = 1):
every episode has the same length and the return is the number of tasks that succeeded.
Robots whose choice would make the workload cap unsatisfiable (`WorkloadCap.feasible_robots`)
are masked out of exploration, of the bootstrap max and of the final greedy policy.

Choices that make it learn well on noisy rewards (measured on the baseline scenario):

- Episodes run in lockstep batches (numpy), and each episode's updates are applied from its
  last task backwards, so a reward reaches the start of the queue in one episode, not n.
- Double Q-learning (van Hasselt 2010): with a single table the max over noisy estimates
  overstated values by several tasks over 36 steps and lured the policy into rarely
  visited states.
- Learning rate 1 / visits (a running mean of the targets): with Bernoulli rewards a
  constant floor, which forgets stale targets, was measurably worse than averaging.
- Optimistic initial values: S[t, a] plus the best S of every later task, an upper bound
  on the expected return, so untried robots look worth trying; the first visit replaces it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field

from app.domain.errors import InfeasibleCapError, TooLargeError
from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo, SolverOptions
from app.solvers.dp import state_bound
from app.solvers.free_part import FreePart

MAX_STATES = 200_000

Loads = tuple[int, ...]


class QLearningOptions(SolverOptions):
    episodes: int = Field(120_000, ge=1, le=200_000, description="training episodes")
    batch_size: int = Field(
        128, ge=1, le=4096, description="episodes run in lockstep between policy refreshes"
    )
    epsilon_start: float = Field(1.0, ge=0.0, le=1.0, description="initial exploration rate")
    epsilon_end: float = Field(0.05, ge=0.0, le=1.0, description="final exploration rate")
    exploration_fraction: float = Field(
        0.8, gt=0.0, le=1.0, description="share of the episodes over which epsilon decays"
    )


@dataclass(frozen=True)
class StateSpace:
    """Every (task index, load vector) reachable without breaking the cap, as integer ids."""

    task: np.ndarray  # (states,) task index t = tasks placed so far
    allowed: np.ndarray  # (states, robots) cap-feasible robots for task t
    successor: np.ndarray  # (states, robots) state id after the move; 0 where not allowed

    @property
    def size(self) -> int:
        return int(self.task.size)


def enumerate_states(part: FreePart) -> StateSpace:
    """States over the free tasks and available robots; loads start from the pins."""
    n, r = part.n_tasks, part.n_robots
    start: Loads = part.initial_loads
    placed = sum(start)
    ids: dict[Loads, int] = {start: 0}
    order: list[Loads] = [start]
    moves: list[list[tuple[int, int]]] = []
    for loads in order:  # grows while iterating: breadth-first, so ids follow task order
        t = sum(loads) - placed
        robots = part.feasible_robots(t, loads) if t < n else []
        row = []
        for robot in robots:
            child = (*loads[:robot], loads[robot] + 1, *loads[robot + 1 :])
            if child not in ids:
                ids[child] = len(order)
                order.append(child)
            row.append((robot, ids[child]))
        moves.append(row)
    allowed = np.zeros((len(order), r), dtype=bool)
    successor = np.zeros((len(order), r), dtype=np.int64)
    for state, row in enumerate(moves):
        for robot, child_id in row:
            allowed[state, robot] = True
            successor[state, robot] = child_id
    task = np.fromiter((sum(loads) - placed for loads in order), dtype=np.int64, count=len(order))
    return StateSpace(task=task, allowed=allowed, successor=successor)


def optimistic_values(space: StateSpace, success: np.ndarray) -> np.ndarray:
    n, r = success.shape
    best_to_go = np.concatenate([np.cumsum(success.max(axis=1)[::-1])[::-1], [0.0]])
    padded = np.vstack([success, np.zeros((1, r))])  # terminal states have no task
    values = padded[space.task] + best_to_go[np.minimum(space.task + 1, n)][:, None]
    return np.where(space.allowed, values, -np.inf)


def _train(
    space: StateSpace, success: np.ndarray, opts: QLearningOptions, rng: np.random.Generator
) -> np.ndarray:
    """Double Q-learning; returns the two tables, shape (2, states, robots)."""
    n, r = success.shape
    q = np.repeat(optimistic_values(space, success)[None], 2, axis=0)
    visits = np.zeros_like(q)
    flat_q, flat_visits = q.reshape(-1), visits.reshape(-1)
    hit_count, target_sum = np.zeros_like(flat_q), np.zeros_like(flat_q)
    per_table = space.size * r
    decay_episodes = max(1.0, opts.exploration_fraction * opts.episodes)
    tasks = np.arange(n)[:, None]
    for start in range(0, opts.episodes, opts.batch_size):
        m = min(opts.batch_size, opts.episodes - start)
        progress = min(1.0, start / decay_episodes)
        epsilon = opts.epsilon_start + (opts.epsilon_end - opts.epsilon_start) * progress
        explore = rng.random((n, m)) < epsilon
        tie_noise = rng.random((n, m, r))
        outcome = rng.random((n, m))
        table = (rng.random(m) < 0.5).astype(np.int64)

        policy = q.sum(axis=0)
        visited = np.empty((n, m), dtype=np.int64)
        chosen = np.empty((n, m), dtype=np.int64)
        state = np.zeros(m, dtype=np.int64)
        for t in range(n):
            greedy = policy[state].argmax(axis=1)
            # Uniform over the allowed robots: random scores, disallowed ones pushed below.
            random = np.where(space.allowed[state], tie_noise[t], -1.0).argmax(axis=1)
            action = np.where(explore[t], random, greedy)
            visited[t], chosen[t] = state, action
            state = space.successor[state, action]
        rewards = (outcome < success[tasks, chosen]).astype(float)

        next_value = np.zeros(m)
        for t in range(n - 1, -1, -1):
            state, action = visited[t], chosen[t]
            target = rewards[t] + next_value
            # Episodes in one batch can share a (table, state, action): average their targets.
            # Duplicate keys then write identical values, so plain fancy assignment is safe.
            key = table * per_table + state * r + action
            np.add.at(hit_count, key, 1.0)
            np.add.at(target_sum, key, target)
            hits, old = hit_count[key], flat_q[key]
            seen = flat_visits[key] + hits
            flat_q[key] = old + hits / seen * (target_sum[key] / hits - old)
            flat_visits[key] = seen
            hit_count[key], target_sum[key] = 0.0, 0.0
            best = q[table, state].argmax(axis=1)
            next_value = q[1 - table, state, best]
    return q


def greedy_policy(space: StateSpace, values: np.ndarray, success: np.ndarray) -> list[int]:
    """Follow the learned values; ties go to the higher success, then the lower robot index."""
    assignment: list[int] = []
    state = 0
    for t in range(success.shape[0]):
        robots = np.flatnonzero(space.allowed[state])
        robot = max(robots, key=lambda i: (values[state, i], success[t, i], -i))
        assignment.append(int(robot))
        state = int(space.successor[state, robot])
    return assignment


class QLearningSolver(Solver):
    info = SolverInfo(
        name="q_learning",
        description="Tabular double Q-learning over (task index, load vector) from sampled "
        "task outcomes, cap-breaking robots masked; approximate (not guaranteed optimal), "
        "seeded and reproducible.",
        exact=False,
        limits=f"at most {MAX_STATES:,} (task, load-vector) states, about C(tasks+robots, "
        "robots); training time grows with episodes x tasks",
    )
    Options = QLearningOptions

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        opts: QLearningOptions = options
        # Trained on the pinned problem: the free tasks, the available robots, the pins' loads.
        part = FreePart.of(problem)
        s = part.success
        n, r = s.shape
        bound = state_bound(n, r)
        if bound > MAX_STATES:
            free = "free " if problem.pinned else ""
            available = "available " if problem.unavailable else ""
            raise TooLargeError(
                "tasks",
                f"q_learning would need a table of up to {bound:,} (task, load-vector) states "
                f"for {n} {free}tasks and {r} {available}robots, above its limit of "
                f"{MAX_STATES:,}; use 'optimal' for this size",
                code="too_large",
            )
        space = enumerate_states(part)
        if n and not space.allowed[0].any():  # Problem.build refuses this; a direct caller may not
            raise InfeasibleCapError("no completion of the free tasks fits the cap from the pins")
        q = _train(space, s, opts, np.random.default_rng(seed))
        choices = greedy_policy(space, q.sum(axis=0), s)
        return Solution(
            part.assignment(choices), details={"states": space.size, "episodes": opts.episodes}
        )

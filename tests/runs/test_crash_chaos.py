"""SIGKILLs in one durable run against the real server, the real SDK and its provider's fake
(openai: Chat Completions, anthropic: the Messages API): the run still ends with an
uninterrupted run's allocation, one decision per task, and no LLM call paid twice.

Ten kills, one at each kind of node (and both sides of `reason`), against one provider;
against the other, the two kills at `reason`, the only node that calls a provider's SDK
(the other nodes read and write the graph's state and the store, whichever reasoner
answers). Each kill is a server start, 3-5 CPU-s (the app's import, then the SDK's at the
resumed run's first call: `import anthropic` alone is 2 CPU-s), so the other eight kills
once more would repeat what the first run proves at about 40 CPU-s
(docs/development.md#tests-and-ci-time)."""

from __future__ import annotations

import random
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from app.graph.builder import NODES
from app.graph.pause import PausePoint
from app.reasoners.rules import compose_answer
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, context_from_prompt, prompt_of
from tests.fakes.llm_providers import PROVIDERS, Provider
from tests.fakes.scripted_reasoner import GARBAGE
from tests.support.server import Server

# Up to eleven server starts: minutes when the suite's other workers share the two cores.
pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]

N_TASKS = 36  # the baseline scenario
RETRY_MARK = "Your previous answer"  # only retry prompts quote the rejected answer


def kill_points(seed: int) -> list[PausePoint]:
    """Ten crash points on ten distinct tasks, in the order the run reaches them: every node
    once, at a random side of it, plus `reason` again at its other side (a kill after the
    reply is recorded, before its checkpoint, is the one that could pay twice)."""
    rng = random.Random(seed)
    sides = {node: rng.random() < 0.5 for node in NODES}
    nodes = [*((node, after) for node, after in sides.items()), ("reason", not sides["reason"])]
    tasks = rng.sample(range(1, N_TASKS), len(nodes))
    points = [
        PausePoint(task, node, after) for task, (node, after) in zip(tasks, nodes, strict=True)
    ]
    return sorted(points, key=lambda p: p.task_index)


def rejecting_first_tries(retry_tasks: set[int]) -> Any:
    """Fake-API responder: unusable first answers on `retry_tasks` (so build_feedback and
    retry run there), a good answer to every other prompt. Pure, so a reference run gets
    the same replies."""

    def respond(request: dict[str, Any]) -> Reply:
        prompt = prompt_of(request)
        ctx = context_from_prompt(prompt)
        if ctx.task_index in retry_tasks and RETRY_MARK not in prompt:
            return Reply.answer(GARBAGE)
        return Reply.answer(compose_answer(ctx))

    return respond


def calls_per_attempt(api: FakeMessagesAPI, first: int = 0) -> Counter[tuple[int, int]]:
    keys = []
    for request in api.requests[first:]:
        prompt = prompt_of(request)
        keys.append((context_from_prompt(prompt).task_index, 2 if RETRY_MARK in prompt else 1))
    return Counter(keys)


# The provider whose run is killed at every kind of node, and the one killed at `reason`
# only (openai's SDK is the cheaper import, so it takes the ten starts).
KILLED_AT = {"openai": set(NODES), "anthropic": {"reason"}}


@pytest.mark.parametrize("provider", [PROVIDERS[name] for name in KILLED_AT], ids=list(KILLED_AT))
def test_sigkills_in_a_durable_run_change_nothing(tmp_path: Path, provider: Provider) -> None:
    every = kill_points(seed=6)
    assert {p.node for p in every} == set(NODES)
    assert {p.after for p in every if p.node == "reason"} == {True, False}
    # The same retries in both runs: where feedback is built and retried, and elsewhere too.
    retry_tasks = {p.task_index for p in every if p.node in ("build_feedback", "retry")}
    retry_tasks |= {every[0].task_index, every[-1].task_index}
    points = [p for p in every if p.node in KILLED_AT[provider.reasoner]]
    assert len(points) == {"openai": 10, "anthropic": 2}[provider.reasoner]  # reason: both sides
    body = {
        "scenario": "baseline",
        "mode": "balanced",
        "reasoner": provider.reasoner,
        "model": provider.model,
    }
    data = tmp_path / "data"

    with provider.fake(default=rejecting_first_tries(retry_tasks)) as api:
        env = provider.env(api)
        server = Server(data, env=env)
        try:
            for n, point in enumerate(points):
                server.start(pause=point)
                if n == 0:
                    with server.client() as c:
                        created = c.post("/runs", json=body)
                    assert created.status_code == 202, created.text
                    run_id = created.json()["id"]
                server.wait_for_log(point.message())
                server.kill()
                server = Server(data, env=env)
        finally:
            server.kill()  # a failure while held must not leave the server running

        server.start()
        try:
            resumed = server.wait_for(run_id, lambda s: s["status"] in ("completed", "failed"))
            chaos_calls = calls_per_attempt(api)
            with server.client() as c:
                trace = c.get(f"/runs/{run_id}/trace").json()
                created = c.post("/runs", json=body)
            reference = server.wait_for(
                created.json()["id"], lambda s: s["status"] in ("completed", "failed")
            )
        finally:
            server.stop()

    assert resumed["status"] == reference["status"] == "completed", (resumed, reference)
    assert [(a["task_id"], a["robot"]) for a in resumed["assignments"]] == [
        (a["task_id"], a["robot"]) for a in reference["assignments"]
    ]
    assert [d["task_index"] for d in trace["decisions"]] == list(range(N_TASKS))
    assert [len(d["attempts"]) for d in trace["decisions"]] == [
        2 if t in retry_tasks else 1 for t in range(N_TASKS)
    ]
    # Every attempt asked the API exactly once, however many times its node re-ran.
    expected = {(t, 1) for t in range(N_TASKS)} | {(t, 2) for t in retry_tasks}
    assert set(chaos_calls) == expected and set(chaos_calls.values()) == {1}, chaos_calls
    assert resumed["usage"]["llm_calls"] == reference["usage"]["llm_calls"] == len(expected)

    assert resumed["resumes"] == len(points)
    resumes = [e["detail"]["integrity"] for e in trace["events"] if e["kind"] == "resumed"]
    assert len(resumes) == len(points)
    assert all(r["ok"] and not r["problems"] for r in resumes), resumes
    # Each resume picked up inside the task it was killed in.
    assert [r["checkpoint_task_index"] for r in resumes] == [p.task_index for p in points]

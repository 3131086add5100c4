"""A real Reasoner whose answers follow a script: for driving the graph through retries.

Each script item is a fixed text or a function of the DecisionContext; after the script
runs out, `then` answers (default: the rules reasoner's answer).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from app.domain.decision import DecisionContext
from app.reasoners.base import ReasonerError, ReasonerReply
from app.reasoners.rules import compose_answer
from app.reasoners.structured import ReplySchema

Answer = str | Callable[[DecisionContext], str] | ReasonerError


@dataclass
class Call:
    task_index: int
    tier: int
    system: str
    user: str


@dataclass
class ScriptedReasoner:
    script: list[Answer] = field(default_factory=list)
    then: Answer = compose_answer
    model: str | None = "scripted"  # a model name makes its replies count as LLM calls
    tokens: tuple[int, int] = (100, 50)
    name: str = "scripted"
    calls: list[Call] = field(default_factory=list)

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        self.calls.append(Call(context.task_index, context.tier, system, user))
        item = self.script.pop(0) if self.script else self.then
        if isinstance(item, ReasonerError):
            raise item
        text = item(context) if callable(item) else item
        return ReasonerReply(
            text=text,
            input_tokens=self.tokens[0],
            output_tokens=self.tokens[1],
            latency_ms=1.0,
            model=self.model,
        )


def poor_answer(ctx: DecisionContext) -> str:
    """A parseable decision for the right robot with almost everything else wrong (Q < 0.6)."""
    label = ctx.robot_labels[compose_choice(ctx)]
    return f"**Decision**: {label}\n**Expected Success**: 3%\n**Confidence Level**: Low"


def compose_choice(ctx: DecisionContext) -> int:
    from app.reasoners.rules import choose

    return choose(ctx)[0]


GARBAGE = "I am not sure which robot should do this; maybe ask a supervisor?"

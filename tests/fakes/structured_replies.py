"""What the fake LLM servers answer when a request asks for a structured reply
(docs/reasoners.md#structured-replies): the markdown answer they would have given, as the
JSON object the request's schema describes, the way a constrained sampler writes it (each
string cut to its maxLength, a robot only from its enum, every required field, nothing
else). A scripted reply that is already JSON is sent as it is, so a test can send one that
breaks its schema; a scripted markdown reply that names no decision comes out as an object
missing its required fields, as an unusable structured reply is.
"""

from __future__ import annotations

import json
import re
from typing import Any

from app.graph.parsing import parse_probability, split_sections
from app.reasoners.structured import looks_structured

_COUNT = re.compile(r"([^,:=]+?)\s*[:=]\s*(\d+)")
_TEAM_LINE = re.compile(r"^\s*[-*]\s*([^:]+):\s*(.+?)\s+[—–-]+\s+(.*)$")


def asked_schema(request: dict[str, Any]) -> dict[str, Any] | None:
    """The JSON Schema a request asks its reply in: Chat Completions' response_format
    (json_schema, or llama-cpp-python's json_object + schema) or a forced tool's input."""
    fmt = request.get("response_format")
    if isinstance(fmt, dict):
        if fmt.get("type") == "json_schema":
            return dict(fmt.get("json_schema", {}).get("schema") or {})
        if fmt.get("type") == "json_object":
            return dict(fmt.get("schema") or {"type": "object"})
    choice = request.get("tool_choice")
    if isinstance(choice, dict) and choice.get("type") == "tool":
        for tool in request.get("tools") or []:
            if tool.get("name") == choice.get("name"):
                return dict(tool.get("input_schema") or {})
    return None


def _cut(text: str, limit: int | None) -> str:
    """`text` within `limit` characters, ending at a sentence where one fits."""
    if limit is None or len(text) <= limit:
        return text
    head = text[:limit]
    end = max(head.rfind(". "), head.rfind(".\n"))
    return head[: end + 1] if end > limit // 3 else head.rstrip()


def _string(schema: dict[str, Any], value: str) -> str:
    return _cut(value, schema.get("maxLength"))


def _named(value: str, allowed: list[str]) -> str:
    """The enum member the text names (a label, any case), else the text itself."""
    lowered = value.strip().lower()
    for name in sorted(allowed, key=len, reverse=True):
        if name.lower() in lowered:
            return name
    return value.strip()


def as_structured(text: str, schema: dict[str, Any]) -> str:
    """The JSON reply to a structured request whose markdown answer is `text`."""
    if looks_structured(text):
        return text
    sections = split_sections(text)
    props: dict[str, Any] = schema.get("properties") or {}
    out: dict[str, Any] = {}
    decision = sections.get("decision", "").splitlines()
    if decision and "decision" in props:
        out["decision"] = _named(decision[0], props["decision"].get("enum") or [])
    if "team" in props and sections.get("team"):
        item = props["team"]["items"]["properties"]
        out["team"] = [
            {
                "feature": m.group(1).strip(),
                "robot": _named(m.group(2), item["robot"].get("enum") or []),
                "reason": _string(item["reason"], m.group(3).strip()),
            }
            for line in sections["team"].splitlines()
            if (m := _TEAM_LINE.match(line))
        ]
    success = parse_probability(sections.get("expected_success", ""))
    if success is not None:
        out["expected_success"] = round(success * 100, 1)
    for key, section in (("reasoning", "reasoning"), ("tradeoff", "tradeoff")):
        if sections.get(section) and key in props:
            out[key] = _string(props[key], sections[section])
    if sections.get("workload_after") and "workload_after" in props:
        names = list(props["workload_after"].get("properties") or {})
        counts = {
            _named(m.group(1), names): int(m.group(2))
            for m in _COUNT.finditer(sections["workload_after"])
        }
        out["workload_after"] = {name: counts[name] for name in names if name in counts}
    if sections.get("confidence"):
        out["confidence"] = sections["confidence"].split()[0].capitalize()
    return json.dumps(out)

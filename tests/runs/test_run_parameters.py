"""The run parameters are defined once (app.runs.spec.RUN_PARAMETERS): the request schema,
the run order and the run spec carry exactly the parameters the table names, so a field
added to one and not to the table fails here instead of being silently dropped."""

from __future__ import annotations

from dataclasses import fields

from app.runs.schemas import RunRequest
from app.runs.spec import ORDER_INSTANCE_FIELDS, RUN_PARAMETERS, RunOrder, RunSpec

NAMES = {p.name for p in RUN_PARAMETERS}


def test_the_run_order_is_the_instance_and_the_parameters_of_the_table() -> None:
    order = {f.name for f in fields(RunOrder)} - {"sent"}
    assert order == set(ORDER_INSTANCE_FIELDS) | NAMES


def test_every_request_field_reaches_the_order() -> None:
    assert set(RunRequest.model_fields) == set(ORDER_INSTANCE_FIELDS) | NAMES


def test_the_spec_stores_every_parameter() -> None:
    assert {f.name for f in fields(RunSpec)} >= NAMES


def test_a_replay_repeats_parameters_and_the_event_shows_some() -> None:
    repeatable = [p.name for p in RUN_PARAMETERS if p.repeatable]
    assert "reasoner" not in repeatable and "objective" not in repeatable
    assert {"mode", "max_deviation", "seed", "review", "site"} <= set(repeatable)
    assert [p.name for p in RUN_PARAMETERS if p.shown] == ["reasoner", "mode"]

"""Webhooks: signed, durable notifications of run events (docs/webhooks.md).

Layering: `app.runs` writes run events and calls `outbox.enqueue_for_event` in the same
transaction; the dispatcher delivers; `app.webhooks.endpoints` manages subscriptions.
Nothing here imports `app.runs`.
"""

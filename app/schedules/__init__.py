"""A run's schedule over HTTP (docs/schedules.md#reading-a-runs-schedule): GET
/runs/{id}/schedule (`endpoints.py`), the current plan in time (app.plans.current) read by
app.schedule_views as JSON, CSV, iCalendar or MS Project XML.

A feature above the living plans, whose re-timed schedule it serves; the pure readers it
calls sit low, in app.schedule_views, because allocation, runs, the console and the
command line call them too (a package is one layer: the readers cannot share this one).
"""

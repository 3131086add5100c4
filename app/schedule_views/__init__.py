"""Reading a schedule (docs/schedules.md#reading-a-runs-schedule): the same plan as JSON, CSV,
iCalendar, a Gantt chart (SVG) and a terminal timeline.

Pure functions over domain objects (a `Problem` and the `Schedule` a solver made of it):
they compute nothing a schedule does not already say, so every view shows the same times.
The API, the console and the command line call them; they import only the domain.
"""

from __future__ import annotations

from app.schedule_views.calendar import schedule_ics
from app.schedule_views.gantt import gantt_svg
from app.schedule_views.json_view import lanes, schedule_json, violations_json
from app.schedule_views.table import schedule_csv
from app.schedule_views.timeline import render_timeline

__all__ = [
    "gantt_svg",
    "lanes",
    "render_timeline",
    "schedule_csv",
    "schedule_ics",
    "schedule_json",
    "violations_json",
]

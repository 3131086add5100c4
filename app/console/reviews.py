"""GET /console/reviews: the queue of decisions waiting for a supervisor."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response

from app.console.context import ConsoleDep, SignedInDep, finish

router = APIRouter(prefix="/console", include_in_schema=False)


@router.get("/reviews")
async def reviews_page(request: Request, console: ConsoleDep, signed: SignedInDep) -> Response:
    # Reviews (SPEC section 11, issue 12) are not in this build: no run can wait for one.
    # templates/reviews.html already renders the queue and its approve / override forms
    # from GET /reviews' item shape; this route passes them once the service exists.
    context = {"title": "Reviews", "reviews": [], "available": False}
    return finish(request, console.render(request, "reviews.html", context, signed=signed))

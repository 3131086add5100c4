"""What the server serves: `uvicorn app.asgi:create_app --factory` (scripts/serve.sh, the
Docker image, `make run`, `ltaa serve`); app.main's factory, imported with the cyclic
garbage collector paused.

Importing the app creates a few hundred thousand long-lived objects (modules, classes,
pydantic and SQLAlchemy models, LangGraph's and FastAPI's machinery), and the collector
walks all of them again at every full collection it triggers meanwhile, freeing nothing:
measured, about a fifth of the import's CPU (0.35-0.45 s of 1.9 s per server start, and
the end-to-end suite starts a server some 150 times). Once imported they are moved to the
permanent generation (`gc.freeze`), so the collections that runs trigger later do not walk
them either; anything created after that is collected as usual.
"""

from __future__ import annotations

import gc

gc.disable()
try:
    from app.main import create_app
finally:
    gc.enable()
gc.freeze()

__all__ = ["create_app"]

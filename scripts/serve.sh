#!/bin/sh
# Serve (the app applies the migrations as it starts, under PostgreSQL's advisory lock when
# several processes start at once). `make run` and the Docker image both start the service
# through this script, so there is one way to start it.
set -eu
HOST="${HOST:-127.0.0.1}"
PORT="${PORT:-8000}"
# The app refuses to listen beyond loopback without API keys: it must know the address
# (and names it, port included, in its start-up warning).
export LTAA_HOST="$HOST" LTAA_PORT="$PORT"
BIN="${LTAA_BIN:-}"
exec "${BIN}uvicorn" app.asgi:create_app --factory --host "$HOST" --port "$PORT"

# syntax=docker/dockerfile:1
# LTAA allocation service: the same commands as the README's `make run`, in a container.
# The `rl` extra (PyTorch, for the dqn solver) is left out by default: PyPI's Linux torch
# wheels are multi-GB CUDA builds. Build with --build-arg EXTRAS=rl to include it.

FROM python:3.11-slim AS build
ARG EXTRAS=""
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
WORKDIR /src
RUN python -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH
# Dependencies first, in their own layer: they change far less often than the code.
COPY pyproject.toml README.md ./
# pip's own configuration, where the build's network needs one (a private index, a proxy
# that re-signs TLS): a pip.conf and a CA bundle as build secrets, e.g.
#   docker build --secret id=pip.conf,src=my-pip.conf --secret id=pip-ca,src=ca.crt .
# (my-pip.conf naming `cert = /run/secrets/pip-ca`). Mounted for one step each, they land
# in no layer and not in the image's history; without them pip uses PyPI and its own CAs.
# Versions are pinned in pyproject.toml, which hadolint cannot see.
# hadolint ignore=DL3013
RUN --mount=type=secret,id=pip.conf,target=/etc/pip.conf \
    --mount=type=secret,id=pip-ca \
    mkdir -p app benchmarks && touch app/__init__.py benchmarks/__init__.py \
    && pip install ".${EXTRAS:+[$EXTRAS]}" \
    && pip uninstall -y ltaa
COPY app ./app
COPY benchmarks ./benchmarks
# The wheel carries the migrations (app/store/migrations): the app applies them as it starts.
RUN --mount=type=secret,id=pip.conf,target=/etc/pip.conf \
    --mount=type=secret,id=pip-ca \
    pip install --no-deps .

FROM python:3.11-slim
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    LTAA_DATA_DIR=/data \
    HOST=0.0.0.0 \
    PORT=8000
RUN groupadd --system --gid 10001 ltaa \
    && useradd --system --uid 10001 --gid ltaa --home-dir /srv ltaa \
    && mkdir -p /data && chown 10001:10001 /data
COPY --from=build /opt/venv /opt/venv
WORKDIR /srv
COPY scripts/serve.sh ./scripts/serve.sh
USER 10001:10001
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=3s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:' + os.environ.get('PORT', '8000') + '/health', timeout=2)"]
CMD ["sh", "scripts/serve.sh"]

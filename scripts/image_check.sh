#!/bin/sh
# make image-check: build the image from the Dockerfile and start it with its own CMD, here,
# without a Docker engine (docs/deployment.md, "Checking the image without Docker"):
#   1. a base tagged python:3.11-slim, made with debootstrap (the registry is out of reach);
#   2. buildah builds the Dockerfile (vfs storage, chroot isolation);
#   3. buildah runs the image's CMD as the image's user in the image's WORKDIR, and the
#      check asks the server for /health, an allocation and a run whose trace verifies.
# Needs root, and `apt-get install -y buildah debootstrap`. Minutes, most of them pip's.
set -eu

ROOT=$(cd "$(dirname "$0")/.." && pwd)
WORK=${IMAGE_CHECK_DIR:-/var/tmp/ltaa-image-check}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
IMAGE=localhost/ltaa:image-check
BASE=docker.io/library/python:3.11-slim
# Its own storage, away from any other buildah user's; vfs: no overlay mounts needed.
STORAGE="--root $WORK/storage --runroot $WORK/runroot --storage-driver vfs"

say() { printf '== %s\n' "$*" >&2; }
bah() {
    # shellcheck disable=SC2086  # STORAGE is a list of options
    buildah $STORAGE "$@"
}

for tool in buildah debootstrap curl python3; do
    command -v "$tool" >/dev/null || {
        echo "image-check needs $tool: apt-get install -y buildah debootstrap curl python3" >&2
        exit 2
    }
done
mkdir -p "$WORK"

# 1. The base. python:3.11-slim is Debian bookworm with Python 3.11 and `python` on PATH;
# this one is Debian's python3.11 (with venv, for `python -m venv`; debootstrap does not
# resolve its python3.11-distutils, which python3-distutils provides), plus what the slim
# image also has and the Dockerfile uses: CA certificates and useradd/groupadd (passwd).
if bah inspect --type image "$BASE" >/dev/null 2>&1; then
    say "base $BASE: already built (IMAGE_CHECK_DIR=$WORK; delete it to rebuild)"
else
    say "base $BASE: debootstrap bookworm minbase"
    rm -rf "$WORK/base"
    debootstrap --variant=minbase --include=python3.11,python3.11-venv,python3-distutils,ca-certificates,passwd \
        bookworm "$WORK/base" "$MIRROR" >"$WORK/debootstrap.log" 2>&1 || {
        tail -20 "$WORK/debootstrap.log" >&2
        exit 1
    }
    ln -sf /usr/bin/python3.11 "$WORK/base/usr/local/bin/python"
    rm -rf "$WORK/base/var/cache/apt/archives/"*.deb "$WORK/base/var/lib/apt/lists/"*
    tar -C "$WORK/base" -cf "$WORK/base.tar" .
    ctr=$(bah from scratch)
    bah add "$ctr" "$WORK/base.tar" / >/dev/null
    bah config --env PATH=/usr/local/bin:/usr/local/sbin:/usr/sbin:/usr/bin:/sbin:/bin \
        --env LANG=C.UTF-8 --cmd python3 "$ctr"
    bah commit --quiet --rm "$ctr" "$BASE" >/dev/null
    rm -rf "$WORK/base" "$WORK/base.tar"
fi

# 2. The build. pip in the build needs this machine's pip configuration (its CA bundle:
# the egress proxy here re-signs TLS; an index URL if one is set): handed over as build
# secrets, which the Dockerfile mounts for its pip steps only, never into a layer.
ca=${PIP_CERT:-$(sed -n 's/^cert *= *//p' /etc/pip.conf 2>/dev/null | head -n 1)}
: >"$WORK/pip.conf"
chmod 600 "$WORK/pip.conf"
if [ -n "$ca" ] && [ -f "$ca" ]; then
    printf '[global]\ncert = /run/secrets/pip-ca\n' >>"$WORK/pip.conf"
else
    ca=/dev/null
fi
if [ -n "${PIP_INDEX_URL:-}" ]; then
    grep -q '^\[global\]' "$WORK/pip.conf" || printf '[global]\n' >>"$WORK/pip.conf"
    printf 'index-url = %s\n' "$PIP_INDEX_URL" >>"$WORK/pip.conf"
fi
say "build $IMAGE from $ROOT/Dockerfile"
# No --layers: with vfs every cached layer is a full copy of the tree (gigabytes, and minutes
# to write and delete); one commit per stage. --format docker keeps the HEALTHCHECK.
bah build --isolation chroot --pull=never --format docker \
    --secret id=pip.conf,src="$WORK/pip.conf" --secret id=pip-ca,src="$ca" \
    -t "$IMAGE" -f "$ROOT/Dockerfile" "$ROOT" >"$WORK/build.log" 2>&1 || {
    tail -40 "$WORK/build.log" >&2
    exit 1
}
bah rmi --prune >/dev/null 2>&1 || true # the previous check's image, now untagged
# One container for the checks and the server: with vfs each one is a full copy.
bah rm ltaa-image-check >/dev/null 2>&1 || true
ctr=$(bah from --pull=never --name ltaa-image-check "$IMAGE")
trap 'bah rm "$ctr" >/dev/null 2>&1 || true' EXIT
if bah run --isolation chroot "$ctr" -- python -c "import torch" >/dev/null 2>&1; then
    echo "the image has torch: the rl extra must stay out by default" >&2
    exit 1
fi

# 3. Start the image's own CMD as its USER in its WORKDIR. chroot isolation shares this
# machine's network: the image's HOST (0.0.0.0) on a free port, with API keys, since the
# app refuses to listen beyond loopback without them.
cmd=$(bah inspect --type image --format '{{range .OCIv1.Config.Cmd}}{{.}} {{end}}' "$IMAGE")
user=$(bah inspect --type image --format '{{.OCIv1.Config.User}}' "$IMAGE")
workdir=$(bah inspect --type image --format '{{.OCIv1.Config.WorkingDir}}' "$IMAGE")
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("", 0)); print(s.getsockname()[1])')
client=$(python3 -c 'import secrets; print(secrets.token_urlsafe(24))')
supervisor=$(python3 -c 'import secrets; print(secrets.token_urlsafe(24))')
say "run '$cmd' as $user in $workdir, port $port"
# buildah itself in the background (not the bah function, a subshell that would not pass
# a signal on): it forwards SIGTERM to the server, which stops as it would in Docker.
# shellcheck disable=SC2086  # cmd is the image's CMD, split into its words
buildah $STORAGE run --isolation chroot --user "$user" --workingdir "$workdir" --env PORT="$port" \
    --env LTAA_API_KEYS="$client:client,$supervisor:supervisor" "$ctr" -- $cmd \
    >"$WORK/serve.log" 2>&1 &
server=$!
stop() {
    kill "$server" 2>/dev/null || true
    wait "$server" 2>/dev/null || true
    bah rm "$ctr" >/dev/null 2>&1 || true
}
trap stop EXIT

url="http://127.0.0.1:$port"
i=0
until curl -sf "$url/health" >/dev/null; do
    i=$((i + 1))
    if [ $i -gt 120 ] || ! kill -0 "$server" 2>/dev/null; then
        echo "the image's server did not answer /health:" >&2
        tail -40 "$WORK/serve.log" >&2
        exit 1
    fi
    sleep 1
done
say "GET /health: $(curl -sf "$url/health")"

# json EXPR: EXPR over the JSON document on stdin, `d`.
json() { python3 -c "import json, sys; d = json.load(sys.stdin); print($1)"; }
c() { curl -sf -H "Authorization: Bearer $client" -H 'content-type: application/json' "$@"; }
s() { curl -sf -H "Authorization: Bearer $supervisor" "$@"; }

n=$(c -X POST "$url/allocate" -d '{"solver":"dp","scenario":"baseline"}' | json 'len(d["assignments"])')
say "POST /allocate (dp, baseline): $n assignments"
[ "$n" -gt 0 ]

run=$(c -X POST "$url/runs" -d '{"scenario":"baseline","reasoner":"rules"}' | json 'd["id"]')
i=0
until [ "$(c "$url/runs/$run" | json 'd["status"]')" = completed ]; do
    i=$((i + 1))
    [ $i -le 120 ] || {
        echo "run $run did not complete: $(c "$url/runs/$run")" >&2
        exit 1
    }
    sleep 1
done
verify=$(s "$url/runs/$run/trace/verify")
say "POST /runs -> $run completed; GET /runs/$run/trace/verify: $verify"
[ "$(echo "$verify" | json 'd["ok"]')" = True ]
version=$(bah run --isolation chroot "$ctr" -- python -c \
    "import sqlite3; print(sqlite3.connect('/data/ltaa.db').execute('SELECT version_num FROM alembic_version').fetchone()[0])")
say "the store in /data is at migration $version"
say "image-check: the image serves (image $IMAGE, logs in $WORK)"

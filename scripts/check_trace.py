"""Check a run's exported audit record offline: its hash chains and, if it was signed, the
signature over its heads, with the server's public key and no secret.

    .venv/bin/python scripts/check_trace.py run-<id>.jsonl [public-key.pem ...]

The record is `GET /runs/<id>/trace?format=jsonl` (or an archive file); the keys are the
`public_key_pem` values of `GET /audit/public-key` (current and retired). Exit 0 when the
record verifies, 1 with the reason otherwise. Every chain scheme in use verifies: the
genesis of each chain is recomputed from the run line by the run's own scheme. The
annotation chain (sign-offs, execution reports after completion) is checked too, and every
sign-off's heads must be the heads of the decision and event chains (as trace/verify's
`signoffs_ok`). An export made before annotation lines existed has none and still verifies.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from app.audit.signing import key_id, payload_bytes
from app.store import chain


def check(lines: list[dict[str, Any]], keys: dict[str, Ed25519PublicKey]) -> tuple[bool, str]:
    # An archive file adds a `verify` line after `end`: the record is what precedes it.
    ends = [i for i, line in enumerate(lines) if line.get("type") == "end"]
    lines = lines[: ends[-1] + 1] if ends else lines
    run = lines[0]
    if run.get("type") != "run" or lines[-1].get("type") != "end":
        return False, "not a whole record: it must start with a run line and end with an end line"
    # A revision's chains hang off its link to the parent (the first event, `revised`): the
    # anchor is recomputed from that event, so an edited link breaks the chains.
    first = next((line for line in lines[1:-1] if line["type"] == "event"), None)
    anchor = (
        chain.revision_anchor(chain.revision_link(first["detail"]))
        if first is not None and first["kind"] == "revised"
        else None
    )
    prev = {
        table: chain.run_genesis(
            table,
            run["id"],
            scheme=run.get("chain_scheme"),
            request=run["request"],
            mode=run["mode"],
            max_deviation=run["max_deviation"],
            anchor=anchor,
        )
        for table in ("decisions", "events")
    }
    geneses = dict(prev)
    # Annotations are chained from a genesis of their own, whatever the run's scheme.
    annotations = chain.genesis("annotations", run["id"])
    counted = {"events": 0, "decisions": 0, "annotations": 0}
    signed_heads: list[Any] = []
    for line in lines[1:-1]:
        kind = line.get("type")
        if kind == "event":
            link = chain.event_link(prev["events"], line)
            where = f"event {line['seq']}"
        elif kind == "decision":
            digest = chain.attempts_digest(line["attempt_records"])
            link = chain.decision_link(prev["decisions"], line, digest)
            where = f"decision {line['task_index']}"
        elif kind == "annotation":
            expected_seq = counted["annotations"] + 1
            if line["seq"] != expected_seq:
                return False, f"annotation {expected_seq} is missing (the next is {line['seq']})"
            link = chain.annotation_link(annotations, line)
            where = f"annotation {line['seq']}"
        else:
            return False, f"unknown line type {kind!r}"
        if link != line["chain_hash"]:
            return False, f"broken at {where}"
        if kind == "annotation":
            annotations = link
            if line["kind"] == "signoff":
                signed_heads.append((line["seq"], (line.get("detail") or {}).get("heads")))
        else:
            prev["events" if kind == "event" else "decisions"] = link
        counted[f"{kind}s"] += 1
    # The end line is outside the chains, but a cut-off or trimmed file shows in its counts
    # (the newest rows of a chain leave no gap when dropped).
    for table, n in counted.items():
        if table in lines[-1] and lines[-1][table] != n:
            return False, f"the end line counts {lines[-1][table]} {table}, the record has {n}"
    heads = {t: (prev[t] if prev[t] != geneses[t] else None) for t in prev}
    for seq, signed in signed_heads:
        if signed != heads:
            return (
                False,
                f"sign-off (annotation {seq}) signed heads {signed}, the record's are {heads}",
            )
    annotations_head = None if counted["annotations"] == 0 else annotations
    heads_text = f"heads: {heads}; annotations head: {annotations_head}"
    signatures = run.get("signatures") or []
    if not signatures:
        return True, f"chains ok (not signed); {heads_text}"
    newest = signatures[-1]
    public = keys.get(newest["key_id"])
    if public is None:
        return False, f"signed with key {newest['key_id']}, which was not given"
    try:
        public.verify(bytes.fromhex(newest["signature"]), payload_bytes(newest["payload"]))
    except (InvalidSignature, ValueError):
        return False, "bad signature: the signed heads were altered"
    if newest["payload"]["heads"] != heads or newest["payload"]["genesis"] != geneses:
        return False, "bad signature: the record's heads differ from the signed ones"
    return True, f"chains ok, signature ok (key {newest['key_id']}); {heads_text}"


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    lines = [json.loads(line) for line in Path(argv[0]).read_text(encoding="utf-8").splitlines()]
    keys: dict[str, Ed25519PublicKey] = {}
    for pem in argv[1:]:
        public = serialization.load_pem_public_key(Path(pem).read_bytes())
        assert isinstance(public, Ed25519PublicKey), f"{pem} is not an Ed25519 public key"
        keys[key_id(public)] = public
    ok, message = check(lines, keys)
    print(("ok: " if ok else "FAILED: ") + message)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

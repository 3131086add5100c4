"""Links between activities: milestones bridged, and cycles refused.

A milestone takes no time, so its start and end are one instant: a link into it
(`p -X?-> m`, lag a) and a link out of it (`m -?Z-> s`, lag b) together say that s's Z
point is at least b after m, which is at least a after p's X point, so `p -XZ-> s` with
lag a + b says the same with the milestone gone (exact when nothing else holds the
milestone back, as nothing does once it is not planned).

A cycle of links is refused whatever its lags, as a request's is
(docs/schedules.md#links): planners place each task after its predecessors, and P6 and MS
Project refuse circular relationships themselves, so a file that holds one is broken.
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence

from app.domain.links import find_cycle
from app.exchange.errors import ExchangeError
from app.exchange.model import Link, LinkType


def bridge_milestones(links: Iterable[Link], milestones: Sequence[str]) -> list[Link]:
    """The links with every milestone replaced by links from its predecessors to its
    successors (milestones chained to milestones included); links between the same two
    activities of the same type keep the largest lag, the one that binds."""
    into: dict[str, list[Link]] = defaultdict(list)
    out_of: dict[str, list[Link]] = defaultdict(list)
    live: set[Link] = set()
    order: list[Link] = []

    def add(link: Link) -> None:
        if link in live:
            return
        live.add(link)
        order.append(link)
        into[link.successor].append(link)
        out_of[link.predecessor].append(link)

    for link in links:
        add(link)
    for m in milestones:
        ins = [k for k in into.pop(m, []) if k in live]
        outs = [k for k in out_of.pop(m, []) if k in live]
        for k in (*ins, *outs):
            live.discard(k)
        for a in ins:
            for b in outs:
                if a.predecessor == m or b.successor == m:
                    continue  # a milestone linked to itself says nothing about others
                kind: LinkType = f"{a.type[0]}{b.type[1]}"  # type: ignore[assignment]
                add(Link(a.predecessor, b.successor, kind, round(a.lag + b.lag, 1)))
    best: dict[tuple[str, str, str], Link] = {}
    for link in order:
        if link in live:
            key = (link.predecessor, link.successor, link.type)
            if key not in best or link.lag > best[key].lag:
                best[key] = link
    return list(best.values())


def refuse_cycles(links: Sequence[Link], ids: Mapping[str, str]) -> None:
    """ExchangeError naming a cycle of links, if there is one (`ids`: the tasks' keys to
    their ids, in the file's order)."""
    keys = list(ids)
    index = {k: i for i, k in enumerate(keys)}
    preds: list[list[int]] = [[] for _ in keys]
    for link in links:
        preds[index[link.successor]].append(index[link.predecessor])
    cycle = find_cycle(preds)
    if not cycle:
        return
    steps = []
    for a, b in itertools.pairwise(cycle):
        steps.append(next(k for k in links if k.predecessor == keys[a] and k.successor == keys[b]))
    _refuse(steps, ids)


def _refuse(cycle: Sequence[Link], ids: Mapping[str, str]) -> None:
    def lag(x: float) -> str:
        return f"{x:+g} min"

    path = " -> ".join(f"{ids[k.predecessor]} ({k.type} {lag(k.lag)})" for k in cycle)
    path += f" -> {ids[cycle[0].predecessor]}"
    raise ExchangeError(
        f"the links form a cycle: {path}; a plan places each task after its predecessors, so "
        "no cycle can be planned, whatever its lags (P6 and MS Project refuse circular "
        "relationships too). Remove one of these links in the file and import it again",
        code="link_cycle",
        field="links",
    )

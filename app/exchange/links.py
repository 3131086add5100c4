"""Links between activities: milestones bridged, and cycles no schedule can meet refused.

A milestone takes no time, so its start and end are one instant: a link into it
(`p -X?-> m`, lag a) and a link out of it (`m -?Z-> s`, lag b) together say that s's Z
point is at least b after m, which is at least a after p's X point, so `p -XZ-> s` with
lag a + b says the same with the milestone gone (exact when nothing else holds the
milestone back, as nothing does once it is not planned).

A cycle of links is not always wrong (two start-to-start links with lag 0 only say two
tasks start together); it is wrong when going round it, with each task's duration between
its start and its end, adds up to more than zero: a positive cycle in the longest-path
graph over start and end points (the lags summed along it, durations counted, above zero).
Only strongly connected parts of the link graph can hold a cycle, so the Bellman-Ford
search runs there alone and an acyclic 10,000-task file costs one linear pass.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence

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


def _components(nodes: Sequence[str], succ: Mapping[str, list[str]]) -> list[list[str]]:
    """Strongly connected components (Tarjan's, iterative: files hold 10,000-task chains)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in nodes:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = len(index)
                stack.append(v)
                on_stack.add(v)
            children = succ.get(v, [])
            if i < len(children):
                work.append((v, i + 1))
                w = children[i]
                if w not in index:
                    work.append((w, 0))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            if low[v] == index[v]:
                part: list[str] = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    part.append(w)
                    if w == v:
                        break
                found.append(part)
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return found


def _edges(link: Link) -> tuple[tuple[str, str], tuple[str, str]]:
    """(from point, to point) of a link: the successor's point is at least lag after it."""
    frm = (link.predecessor, "start" if link.type[0] == "S" else "end")
    to = (link.successor, "start" if link.type[1] == "S" else "end")
    return frm, to


def refuse_positive_cycles(
    links: Sequence[Link], durations: Mapping[str, float], ids: Mapping[str, str]
) -> None:
    """ExchangeError naming a cycle of links that no schedule can meet, if there is one."""
    succ: dict[str, list[str]] = defaultdict(list)
    for link in links:
        succ[link.predecessor].append(link.successor)
    parts = _components(list(durations), succ)
    part_of = {t: i for i, part in enumerate(parts) for t in part}
    inner: dict[int, list[Link]] = defaultdict(list)
    for link in links:
        if part_of[link.predecessor] == part_of[link.successor]:
            inner[part_of[link.predecessor]].append(link)
    for i, within in inner.items():
        _bellman_ford(parts[i], within, durations, ids)


def _bellman_ford(
    part: Sequence[str],
    inner: Sequence[Link],
    durations: Mapping[str, float],
    ids: Mapping[str, str],
) -> None:
    Point = tuple[str, str]
    edges: list[tuple[Point, Point, float, Link | None]] = []
    for t in part:
        d = durations[t]
        edges.append(((t, "start"), (t, "end"), d, None))
        edges.append(((t, "end"), (t, "start"), -d, None))
    for link in inner:
        frm, to = _edges(link)
        edges.append((frm, to, link.lag, link))
    dist: dict[Point, float] = {p: 0.0 for t in part for p in ((t, "start"), (t, "end"))}
    via: dict[Point, tuple[Point, Link | None]] = {}
    last: Point | None = None
    for _ in range(len(dist)):
        last = None
        for u, v, w, by in edges:
            if dist[u] + w > dist[v] + 1e-6:
                dist[v] = dist[u] + w
                via[v] = (u, by)
                last = v
        if last is None:
            return
    assert last is not None
    for _ in range(len(dist)):  # step back into the cycle itself
        last = via[last][0]
    cycle: list[Link] = []
    point = last
    while True:
        point, step = via[point]
        if step is not None:
            cycle.append(step)
        if point == last:
            break
    cycle.reverse()
    _refuse(cycle, ids)


def _refuse(cycle: Sequence[Link], ids: Mapping[str, str]) -> None:
    def lag(x: float) -> str:
        return f"{x:+g} min"

    path = " -> ".join(f"{ids[k.predecessor]} ({k.type} {lag(k.lag)})" for k in cycle)
    path += f" -> {ids[cycle[0].predecessor]}"
    raise ExchangeError(
        f"the links form a cycle no schedule can meet: {path}; going round it, the lags and "
        "the tasks' durations add up to more than zero. Remove or change one of these links "
        "in the file and import it again",
        code="link_cycle",
        field="links",
    )

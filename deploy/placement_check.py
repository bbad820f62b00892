"""Before a cluster run starts anything: can the cluster hold it? The components' Ray options (CPUs,
GPUs, custom resources; ``builder.Placement``) against the nodes' total resources (``ray.nodes()``).

Ray would queue an actor that fits no node and the launcher would give up on it after minutes
(``train``'s start timeout); this says it at once, with the numbers, before any actor exists:
a component no single node can hold, a resource the whole cluster has too little of, or a set of
components that first-fit-decreasing cannot pack onto the nodes (Ray's own scheduler packs
differently, so that last one is said as a warning, not a refusal).

Room: deploy, the wiring. May import: the standard library (the launcher hands it plain numbers).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Need:
    """What one component asks Ray for: resource name -> amount (``CPU``, ``GPU``, custom ones)."""

    component: str
    resources: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Verdict:
    refusal: str | None  # the run cannot be placed: one line saying why, with the numbers
    warning: str | None  # it may not be placed: say so and go on


def _fmt(resources: dict[str, float]) -> str:
    return ", ".join(f"{v:g} {k}" for k, v in sorted(resources.items()) if v) or "nothing"


def _fits(need: dict[str, float], free: dict[str, float]) -> bool:
    return all(free.get(k, 0.0) + 1e-9 >= v for k, v in need.items() if v)


def check_placement(needs: list[Need], nodes: list[dict[str, float]]) -> Verdict:
    """``nodes``: each alive node's total resources. Refuses when a component fits no node or the
    cluster's total of a resource is below the run's; warns when first-fit-decreasing over the
    nodes' totals cannot place every component."""
    if not nodes:
        return Verdict("the Ray cluster has no alive node", None)
    for need in needs:
        if not any(_fits(need.resources, node) for node in nodes):
            biggest = max(nodes, key=lambda n: n.get("CPU", 0.0))
            return Verdict(f"{need.component} needs {_fmt(need.resources)} on one node, and no node has that "
                           f"(the largest: {_fmt(biggest)}; {len(nodes)} node{'s' if len(nodes) > 1 else ''})", None)
    total_need: dict[str, float] = {}
    for need in needs:
        for k, v in need.resources.items():
            total_need[k] = total_need.get(k, 0.0) + v
    for k, v in sorted(total_need.items()):
        have = sum(node.get(k, 0.0) for node in nodes)
        if v > have + 1e-9:
            parts: dict[str, float] = {}
            for need in needs:
                kind = "workers" if need.component.startswith("w") and need.component[1:].isdigit() else need.component
                parts[kind] = parts.get(kind, 0.0) + need.resources.get(k, 0.0)
            return Verdict(f"the run needs {v:g} {k} ({', '.join(f'{n} {a:g}' for n, a in parts.items())}) and the "
                           f"cluster has {have:g} on {len(nodes)} node{'s' if len(nodes) > 1 else ''}: fewer workers "
                           f"(--workers) or smaller deploy.*_cpus / *_resources, or a larger cluster", None)
    free = [dict(node) for node in nodes]
    order = sorted(needs, key=lambda n: sorted(n.resources.items(), key=lambda kv: -kv[1])[0][1] if n.resources else 0,
                   reverse=True)
    for need in order:
        node = next((f for f in free if _fits(need.resources, f)), None)
        if node is None:
            return Verdict(None, f"the cluster's totals cover the run, but no packing found here places "
                                 f"{need.component} ({_fmt(need.resources)}) beside the others; Ray may still find one")
        for k, v in need.resources.items():
            node[k] = node.get(k, 0.0) - v
    return Verdict(None, None)

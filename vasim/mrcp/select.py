"""The hierarchy of the action planner: which candidate moves first, toward which point
(spec/mrcp.md §7, seed section 4.4.3, Algorithm 2).

RSel acts first; then the candidates in order of decreasing useful time ``tus``, each
toward its best continuity task point (the point maximising its ``tus``). **Decision**: two
candidates never aim at the same point — in the hierarchy's order each takes its best point
not yet taken (the better-ranked one wins); a candidate with no point of positive ``tus``
left keeps its place in the order with no goal (it only avoids obstacles).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

Key = tuple[str, int]


@dataclass(frozen=True)
class Assignment:
    """A candidate's place in the hierarchy.

    Attributes:
        robot: candidate name.
        point: its goal task point, or None (no useful point: avoid obstacles only).
        tus: its useful time at that point [s] (``-inf`` when no point).
    """

    robot: str
    point: int | None
    tus: float


def candidate_hierarchy(tus: Mapping[Key, float], candidates: Iterable[str],
                        reserved: Iterable[int] = ()) -> list[Assignment]:
    """Order the candidates by their best ``tus`` and give each a distinct goal point.

    Args:
        tus: ``(robot, point) -> tus`` [s] of the candidates' evaluations.
        candidates: every robot that does not hold the task.
        reserved: points nobody may take (CuTP; in TT the point RCnt is grasping).

    Example:
        >>> tus = {("a", 1): 2.0, ("a", 2): 1.0, ("b", 1): 3.0, ("b", 2): 0.5}
        >>> [(x.robot, x.point) for x in candidate_hierarchy(tus, ["a", "b"])]
        [('b', 1), ('a', 2)]
    """
    taken = set(reserved)
    rows = {r: sorted(((v, q) for (rr, q), v in tus.items()
                       if rr == r and v > 0.0 and q not in taken),
                      key=lambda vq: (-vq[0], vq[1]))
            for r in candidates}
    order = sorted(rows, key=lambda r: (-(rows[r][0][0] if rows[r] else float("-inf")), r))
    out: list[Assignment] = []
    for r in order:
        choice = next(((v, q) for v, q in rows[r] if q not in taken), None)
        if choice is None:
            out.append(Assignment(r, None, float("-inf")))
            continue
        taken.add(choice[1])
        out.append(Assignment(r, choice[1], choice[0]))
    return out

"""Grasp and place poses of the flange case, derived from the models' frames.

Nothing here is typed in per slot: a token names seat frames (`slot_k` on `base_plate`, `row_j` on
`square_flange`), a part's pose follows the conventions in docs/conventions.md, and the gripper's
`tcp` takes the part's `grasp` frame.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix

from hrc_drake.tasks.tokens import UNDO, Placement, parse_base_token

# Spec part symbol -> model instances, in the order free ones are taken from the tray.
PART_INSTANCES: Mapping[str, tuple[str, ...]] = {
    "F": ("oval_flange_1", "oval_flange_2"),
    "S": ("square_flange",),
}
# Host tag in a token -> the symbol of the host part (`F01`: an F on the square over slot 1).
HOST_TAGS: Mapping[str, str] = {"0": "S"}

_SYMBOL = re.compile(r"^(?P<part>[A-Z][A-Za-z]*)(?P<rest>.+)$")


def parse_token(token: str, host_tags: Mapping[str, str] = HOST_TAGS) -> Placement:
    """Parse a placement token (`F1`, `S12`, `F01`) into a Placement; ValueError if not one."""
    match = _SYMBOL.match(token)
    if match is None or token == UNDO:
        raise ValueError(f"{token!r} is not a placement token")
    part, rest = match["part"], match["rest"]
    for tag, host in host_tags.items():
        if rest.startswith(tag) and len(rest) > len(tag):
            where = rest[len(tag) :].lstrip("-")
            _, slots = parse_base_token(f"{part}{where}")
            placement = Placement(part, slots, host=host, host_tag=tag)
            if placement.token == token:
                return placement
    _, slots = parse_base_token(token)
    return Placement(part, slots)


@dataclass(frozen=True)
class CellFrames:
    """World poses of the seats and tray homes, and each part's fixed frames.

    Attributes:
        seats: `slot_k` (k = base slot) -> X_W_slot.
        homes: part instance -> X_W_part at rest in the tray (`home_<instance>`).
        rows: host instance -> row index j -> X_host_row_j.
        grasps: part instance -> X_part_grasp.
        widths: part instance -> width between the fingers when held [m].
        tray: X_W_tray, the tray's body frame.
    """

    seats: Mapping[int, RigidTransform]
    homes: Mapping[str, RigidTransform]
    rows: Mapping[str, Mapping[int, RigidTransform]]
    grasps: Mapping[str, RigidTransform]
    widths: Mapping[str, float]
    tray: RigidTransform = field(default_factory=RigidTransform)
    part_instances: Mapping[str, tuple[str, ...]] = field(default_factory=lambda: PART_INSTANCES)
    host_tags: Mapping[str, str] = field(default_factory=lambda: HOST_TAGS)

    def with_seat(self, slot: int, X_W_slot: RigidTransform) -> CellFrames:
        """A copy with base slot `slot` moved to `X_W_slot` (tests: an unreachable seat)."""
        return replace(self, seats={**self.seats, slot: X_W_slot})

    def with_homes(self, homes: Mapping[str, RigidTransform]) -> CellFrames:
        """A copy with some parts' tray homes (X_W_part) replaced."""
        return replace(self, homes={**self.homes, **homes})

    def symbol_of(self, instance: str) -> str:
        """The spec symbol of a part instance."""
        for symbol, instances in self.part_instances.items():
            if instance in instances:
                return symbol
        raise KeyError(f"{instance!r} is not a part instance ({dict(self.part_instances)})")


def midpoint(X_a: RigidTransform, X_b: RigidTransform) -> RigidTransform:
    """The pose halfway between two poses (translation average, rotation slerp)."""
    q_a = X_a.rotation().ToQuaternion()
    q_b = X_b.rotation().ToQuaternion()
    q_mid: Quaternion = q_a.slerp(0.5, q_b)
    return RigidTransform(RotationMatrix(q_mid), 0.5 * (X_a.translation() + X_b.translation()))


def assign_instances(
    frames: CellFrames, configuration: Iterable[str], last_token: str | None = None
) -> dict[str, str]:
    """Which part instance sits at each token of `configuration`.

    Parts are taken from the tray lowest-numbered first and undone last-in first-out, so among
    the tokens of one symbol the one placed last (`last_token`) holds the highest-numbered
    instance; the others are ordered base tokens first, then by token.
    """
    assignment: dict[str, str] = {}
    tokens = sorted(configuration)
    for symbol, instances in frames.part_instances.items():
        placements = [parse_token(t, frames.host_tags) for t in tokens]
        mine = [p for p in placements if p.part == symbol]
        mine.sort(key=lambda p: (p.token == last_token, p.host is not None, p.token))
        if len(mine) > len(instances):
            raise ValueError(f"configuration {tokens} holds more {symbol} than {instances}")
        assignment.update({p.token: inst for p, inst in zip(mine, instances, strict=False)})
    unknown = set(tokens) - set(assignment)
    if unknown:
        raise ValueError(f"configuration holds tokens of unknown parts: {sorted(unknown)}")
    return assignment


def part_pose(frames: CellFrames, token: str, configuration: Iterable[str]) -> RigidTransform:
    """X_W_part of the part placed at `token`, given the other tokens in place.

    A base token sits on its seat frame (the square: midpoint of its two slots); a token on a host
    (`F0k`) sits on the host's row over base slot k, wherever the host sits in `configuration`.
    """
    placement = parse_token(token, frames.host_tags)
    if placement.host is None:
        for slot in placement.slots:
            if slot not in frames.seats:
                raise ValueError(f"{token}: base slot {slot} has no frame slot_{slot}")
        if len(placement.slots) == 1:
            return frames.seats[placement.slots[0]]
        if len(placement.slots) == 2:
            return midpoint(frames.seats[placement.slots[0]], frames.seats[placement.slots[1]])
        raise ValueError(f"{token}: a part over {len(placement.slots)} slots is not supported")
    hosts = [
        p
        for p in (parse_token(t, frames.host_tags) for t in configuration)
        if p.part == placement.host and p.host is None
    ]
    if len(hosts) != 1:
        raise ValueError(f"{token} needs exactly one {placement.host} on the base, not {hosts}")
    host = hosts[0]
    (slot,) = placement.slots
    if slot not in host.slots:
        raise ValueError(f"{token}: its host {host.token} does not cover base slot {slot}")
    # row_1 is over the lower-numbered base slot the host covers (conventions).
    row = host.slots.index(slot) + 1
    host_instance = frames.part_instances[host.part][0]
    X_W_host = part_pose(frames, host.token, configuration)
    return X_W_host @ frames.rows[host_instance][row]


def tcp_pose(frames: CellFrames, instance: str, X_W_part: RigidTransform) -> RigidTransform:
    """X_W_tcp when holding `instance` at X_W_part (the tcp takes the part's `grasp` frame)."""
    return X_W_part @ frames.grasps[instance]


def offset_along_approach(X_W_tcp: RigidTransform, distance: float) -> RigidTransform:
    """X_W_tcp moved back `distance` against its approach axis (+z of tcp): pre-grasp, retreat."""
    z = X_W_tcp.rotation().col(2)
    return RigidTransform(X_W_tcp.rotation(), X_W_tcp.translation() - distance * np.asarray(z))

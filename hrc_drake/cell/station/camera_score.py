"""The camera's verdicts scored against the simulator's ground truth (`configuration: camera`).

The contact sensor (`hrc_drake.cell.station.slot_monitor`) stays the truth: at every frame the
camera (`hrc_drake.cell.station.camera`) notes beside its own verdict on each part the contact
sensor's at the frame's instant, as runs of one verdict (`Episode`s). Scored are the verdicts
the controller acts on, `seated` (with its seat and token: a wrong slot is another seat) and
`misplaced`:

- a **false detection** is a run of the camera's verdict that the truth never showed within
  `grace` of it (the camera confirms a change CONFIRM_FRAMES frames late, and may see a part
  within a seat's tolerance a frame or two before its boss touches the floor); a false `seated`
  while the truth shows the part seated elsewhere is also a **wrong slot**;
- a **missed detection** is a run of the truth at least `grace` long that the camera never
  reported while it lasted, or within `grace` after;
- the **detection latency** of a run of the truth the camera reported is from the run's first
  frame to the camera's first frame with that verdict (0 if it saw it first), plus the
  camera's latency.

Values and arithmetic only: no Drake.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hrc_drake.cell.ports import PartStatus

SCORED = (PartStatus.SEATED.value, PartStatus.MISPLACED.value)

Label = tuple[str, tuple[str, ...], str, str]  # camera_verdicts.label: status, seats, host, token


@dataclass(frozen=True)
class Episode:
    """One verdict held from frame time `first` to frame time `last` [s]."""

    label: Label
    first: float
    last: float

    def near(self, other: Episode, grace: float) -> bool:
        """Whether `other` overlaps this run widened by `grace` on both sides."""
        return other.first <= self.last + grace and other.last >= self.first - grace


def _extend(runs: tuple[Episode, ...], label: Label, time: float) -> tuple[Episode, ...]:
    if runs and runs[-1].label == label:
        return (*runs[:-1], Episode(label, runs[-1].first, time))
    return (*runs, Episode(label, time, time))


@dataclass(frozen=True)
class CameraHistory:
    """Per part, the runs of the truth's verdict (`truth`) and of the camera's (`seen`) at its
    frames, and the number of frames."""

    frames: int = 0
    truth: dict[str, tuple[Episode, ...]] = field(default_factory=dict)
    seen: dict[str, tuple[Episode, ...]] = field(default_factory=dict)

    def add(self, time: float, truth: dict[str, Label], seen: dict[str, Label]) -> CameraHistory:
        """The history with one more frame at `time`."""
        return CameraHistory(
            self.frames + 1,
            {p: _extend(self.truth.get(p, ()), v, time) for p, v in truth.items()},
            {p: _extend(self.seen.get(p, ()), v, time) for p, v in seen.items()},
        )


def describe(label: Label) -> str:
    """A verdict in words: `seated F3`, `seated row_1 on square_flange`, `misplaced`."""
    status, seats, host, token = label
    if status != PartStatus.SEATED.value:
        return status
    return f"seated {token}" if token else f"seated {' '.join(seats)} on {host or 'the plate'}"


@dataclass(frozen=True)
class CameraScore:
    """The camera's verdicts against the truth over a run (module docstring)."""

    frames: int
    detections: int
    false_detections: tuple[str, ...]
    missed_detections: tuple[str, ...]
    wrong_slot: int
    latencies: tuple[float, ...]

    def to_json(self) -> dict:
        """`configuration.camera` of the run's JSON."""
        late = self.latencies
        return {
            "frames": self.frames,
            "detections": self.detections,
            "false_detections": len(self.false_detections),
            "missed_detections": len(self.missed_detections),
            "wrong_slot": self.wrong_slot,
            "detection_latency": {
                "mean": round(sum(late) / len(late), 3) if late else None,
                "max": round(max(late), 3) if late else None,
            },
            "events": [*self.false_detections, *self.missed_detections],
        }


def _false(part: str, truth, seen, grace: float) -> tuple[list[str], int]:
    false, wrong = [], 0
    for s in seen:
        if s.label[0] not in SCORED:
            continue
        if any(t.label == s.label and t.near(s, grace) for t in truth):
            continue
        false.append(f"false: {part} read {describe(s.label)} at {s.first:.2f}-{s.last:.2f} s")
        status = PartStatus.SEATED.value
        wrong += s.label[0] == status and any(
            t.label[0] == status and t.near(s, 0.0) for t in truth
        )
    return false, wrong


def score(history: CameraHistory, grace: float, latency: float) -> CameraScore:
    """Score the camera's verdicts in `history` (module docstring); `grace` [s] is how late a
    confirmed verdict may come (CONFIRM_FRAMES periods), `latency` the camera's [s]."""
    false: list[str] = []
    missed: list[str] = []
    late: list[float] = []
    wrong = 0
    for part, truth in sorted(history.truth.items()):
        seen = history.seen.get(part, ())
        found, wrong_here = _false(part, truth, seen, grace)
        false += found
        wrong += wrong_here
        for t in truth:
            if t.label[0] not in SCORED:
                continue
            hits = [s for s in seen if s.label == t.label and t.near(s, grace)]
            if hits:
                late.append(max(0.0, min(s.first for s in hits) - t.first) + latency)
            elif t.last - t.first >= grace:
                missed.append(f"missed: {part} {describe(t.label)} at {t.first:.2f}-{t.last:.2f} s")
    return CameraScore(history.frames, len(late), tuple(false), tuple(missed), wrong, tuple(late))


__all__ = ["CameraHistory", "CameraScore", "Episode", "describe", "score"]

"""Which topic of a log plays which role (IMU, GNSS, wheel, truth): chosen by the user or found
by message type."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from estimator.errors import LogError, TopicError
from estimator.io.messages import FIX_TYPE, IMU_TYPE, ODOM_TYPE, TF_TYPE, TWIST_TYPE

IMU_TYPES = (IMU_TYPE,)
FIX_TYPES = (FIX_TYPE,)
WHEEL_TYPES = (ODOM_TYPE, TWIST_TYPE)


@dataclass(frozen=True)
class TopicChoice:
    """Topics picked by the user; ``None`` lets the loader find the topic by its type.
    ``no_wheel`` leaves the wheel speed out even when the log has it: an IMU-only run of a log
    recorded with an odometer (issue 17's IMU-only cases) reads the same file as the full one."""

    imu: str | None = None
    gnss: str | None = None
    wheel: str | None = None
    truth: str | None = None
    no_wheel: bool = False

    @classmethod
    def from_args(cls, args: Any) -> TopicChoice:
        """From the ``--imu-topic`` ... options of :mod:`inspector.cli.options`."""
        return cls(
            imu=getattr(args, "imu_topic", None),
            gnss=getattr(args, "gnss_topic", None),
            wheel=getattr(args, "wheel_topic", None),
            truth=getattr(args, "truth_topic", None),
            no_wheel=bool(getattr(args, "no_wheel", False)),
        )


AUTO_TOPICS = TopicChoice()
"""Every topic found by its type."""


def is_truth_topic(topic: str) -> bool:
    name = topic.lower()
    return "truth" in name or "groundtruth" in name


@dataclass(frozen=True)
class TopicRoles:
    """The topic read for each role (``None``: the log has none)."""

    imu: str
    gnss: str
    wheel: str | None
    truth: str | None
    truth_pose: str | None
    tf_static: str | None

    def role_of(self, topic: str) -> str:
        for role in ("imu", "gnss", "wheel", "truth", "truth_pose", "tf_static"):
            if getattr(self, role) == topic:
                return role
        return ""


def _listing(types: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m.split('/')[-1]})" for t, m in sorted(types.items())) or "none"


def _pick(
    path: Path,
    types: dict[str, str],
    *,
    kind: str,
    accepted: tuple[str, ...],
    chosen: str | None,
    truth: bool,
    required: bool,
    taken: frozenset[str] = frozenset(),
) -> str | None:
    if chosen is not None:
        if chosen not in types:
            raise LogError(path, f"no topic {chosen} (--{kind}-topic); topics: {_listing(types)}")
        if types[chosen] not in accepted:
            raise LogError(
                path,
                f"--{kind}-topic {chosen} is a {types[chosen]}, expected " + " or ".join(accepted),
            )
        return chosen
    found = sorted(
        t
        for t, m in types.items()
        if m in accepted and is_truth_topic(t) == truth and t not in taken
    )
    if len(found) == 1:
        return found[0]
    if not found:
        if required:
            wanted = " or ".join(a.split("/")[-1] for a in accepted)
            raise LogError(path, f"no {kind.upper()} topic ({wanted}); topics: {_listing(types)}")
        return None
    raise TopicError(
        path,
        f"several {kind} topics: {', '.join(found)}",
        kind=kind,
        found=tuple(found),
        topics=_listing(types),
    )


def topic_roles(path: Path, types: dict[str, str], choice: TopicChoice) -> TopicRoles:
    """Chosen topics first; a topic the user chose for one role is no candidate for another."""
    if choice.no_wheel and choice.wheel is not None:
        raise LogError(path, f"--wheel-topic {choice.wheel} and --no-wheel contradict each other")
    taken = frozenset(t for t in (choice.imu, choice.gnss, choice.wheel, choice.truth) if t)

    def pick(kind: str, accepted: tuple[str, ...], *, truth: bool = False) -> str | None:
        return _pick(
            path,
            types,
            kind=kind,
            accepted=accepted,
            chosen=getattr(choice, kind),
            truth=truth,
            required=kind in ("imu", "gnss"),
            taken=taken,
        )

    imu = pick("imu", IMU_TYPES)
    gnss = pick("gnss", FIX_TYPES)
    wheel = None if choice.no_wheel else pick("wheel", WHEEL_TYPES)
    truth = pick("truth", FIX_TYPES, truth=True)
    poses = sorted(t for t, m in types.items() if m == ODOM_TYPE and is_truth_topic(t))
    truth_pose = poses[0] if truth is not None and len(poses) == 1 else None
    tf = next((t for t, m in types.items() if m == TF_TYPE and t.endswith("tf_static")), None)
    assert imu is not None and gnss is not None
    return TopicRoles(imu, gnss, wheel, truth, truth_pose, tf)

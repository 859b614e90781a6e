"""Episodes an agent ran in AI2-THOR, as adaptenv trajectories (``adaptenv trajectory from-ai2thor``).

The log is JSON lines (optionally gzipped), one object a line:

- optionally first, a header without ``agent``: ``{"house": ID, "target_type": "Bed", "policy": NAME,
  "seed": N}`` (``target_type`` may also be a WordNet synset such as ``bed.n.01``, as SPOC names targets);
- then one record per AI2-THOR event: ``{"action": A, "agent": controller.last_event.metadata["agent"],
  "lastActionSuccess": ...}``. The first record is the start (its action, e.g. a teleport, is
  ignored); each later one is the action just taken and the agent after it. ``"metadata": event.metadata``
  may stand in for ``agent`` and ``lastActionSuccess``.

``A`` is an action name or the dict given to ``controller.step``: AI2-THOR's (``MoveAhead``,
``MoveBack``, ``RotateLeft``, ``RotateRight``, ``MoveAgent`` with ``ahead``, ``RotateAgent`` with
``degrees``, ``Done``, ``Stop``), SPOC's (``m b l r ls rs end``) or adaptenv's (``move_ahead`` ...).
Actions that do not move the agent on the floor (``LookUp``, ``LookDown``, ``Pass``, ``sub_done``, SPOC's
arm and gripper actions) are dropped and counted.

AI2-THOR and adaptenv share the house's frame: ``position.x``/``z`` are the floor coordinates (m) and
``rotation.y`` the yaw (0 faces +z, 90 faces +x, right turns increase it), so poses are copied as they
are (yaw taken modulo 360). The poses are the truth: the converter does not replay the actions. The
metrics, sight and distances are then computed by adaptenv (its 2 m visibility success test at the
recorded poses), so success can differ from AI2-THOR's own judgement.
"""

from __future__ import annotations

import json
import math
import zlib
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from adaptenv.errors import AdaptenvError
from adaptenv.files import FileRefused, gunzip, loads_json, read_bytes
from adaptenv.limits import AI2THOR_LOG_BYTES
from adaptenv.scene.objathor import type_for_name
from adaptenv.sim.metrics import episode_metrics
from adaptenv.sim.rollout import record_sight, target_fields
from adaptenv.sim.spec import ROTATE_LARGE, ROTATE_SMALL, TARGET_TYPES
from adaptenv.sim.trajectory import Pose, Step, Trajectory, metres, pose_jumps, step_jump
from adaptenv.sim.world import NavWorld

_NAMES = {
    **dict.fromkeys(("MoveAhead", "m", "move_ahead"), "m"),
    **dict.fromkeys(("MoveBack", "b", "move_back"), "b"),
    **dict.fromkeys(("RotateLeft", "l", "rotate_left"), "l"),
    **dict.fromkeys(("RotateRight", "r", "rotate_right"), "r"),
    **dict.fromkeys(("ls", "rotate_left_small"), "ls"),
    **dict.fromkeys(("rs", "rotate_right_small"), "rs"),
    **dict.fromkeys(("Done", "done", "end", "Stop", "stop"), "end"),
}
"""Action names -> adaptenv action codes (``spec.ACTIONS``)."""
#: Actions that leave the agent where it stands on the floor: dropped from the trajectory.
NO_FLOOR_MOTION = frozenset({"LookUp", "LookDown", "Pass", "NoOp", "Crouch", "Stand", "sub_done", "yp", "yps", "ym",
                             "yms", "zp", "zps", "zm", "zms", "wp", "wm", "p", "d", "PickupObject", "DropHandObject"})
#: How far (m) a recorded position may lie outside every room (a body in a doorway, float noise).
OUTSIDE_TOLERANCE = 0.3
#: Turns smaller than this (degrees) are the small turns ``ls``/``rs`` (SPOC's 6 degrees), larger ones ``l``/``r``.
SMALL_TURN_BELOW = (ROTATE_SMALL + ROTATE_LARGE) / 2
#: Moves must, on the median, go within about 60 degrees of where the logged yaw faces.
MIN_ALONG_HEADING = 0.5


@dataclass
class AI2ThorLog:
    """A log read from a file: its header and its event records (with their line numbers)."""

    header: dict[str, Any]
    records: list[dict[str, Any]]
    lines: list[int]
    """Line number of each record in the file."""
    source: str = "log"


@dataclass
class Conversion:
    """A converted episode and what was left out of it."""

    trajectory: Trajectory
    dropped: Counter = field(default_factory=Counter)
    """Names of the actions dropped because they do not move the agent on the floor."""


def read_ai2thor_log(path: str | Path) -> AI2ThorLog:
    """Read a JSON-lines (or gzipped) AI2-THOR episode log; AdaptenvError names the file and line."""
    p = Path(path)
    fix = "log one JSON object per line as docs/simulator.md shows"
    try:
        raw = read_bytes(p, AI2THOR_LOG_BYTES, "AI2-THOR log")
        text = (gunzip(raw, AI2THOR_LOG_BYTES, "AI2-THOR log", p) if raw[:2] == b"\x1f\x8b" else raw).decode("utf-8")
    except FileNotFoundError:
        raise AdaptenvError(f"{p}: no such AI2-THOR log; check the path") from None
    except FileRefused:
        raise
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as exc:
        raise AdaptenvError(f"{p}: cannot read it as text or gzipped text ({exc}); {fix}") from None
    rows: list[tuple[int, dict[str, Any]]] = []
    for n, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = loads_json(line)
        except json.JSONDecodeError as exc:
            raise AdaptenvError(f"{p}: line {n} is not JSON ({exc.msg}); {fix}") from None
        except ValueError as exc:  # nested too deeply, or an integer of more than 4300 digits
            raise AdaptenvError(f"{p}: line {n} is refused ({str(exc).split(';')[0]}); {fix}") from None
        if not isinstance(row, dict):
            raise AdaptenvError(f"{p}: line {n} is not a JSON object; {fix}")
        rows.append((n, row))
    header: dict[str, Any] = {}
    if rows and _agent(rows[0][1]) is None:
        header = rows.pop(0)[1]
    if not rows:
        raise AdaptenvError(f"{p}: no event records (objects with \"agent\": controller.last_event.metadata"
                            f"[\"agent\"]); {fix}")
    return AI2ThorLog(header, [r for _, r in rows], [n for n, _ in rows], str(p))


def _agent(record: dict[str, Any]) -> dict[str, Any] | None:
    agent = record.get("agent", (record.get("metadata") or {}).get("agent"))
    return agent if isinstance(agent, dict) else None


def _pose(record: dict[str, Any], where: str) -> Pose:
    """The agent's floor pose in one record (x, z from ``position``, yaw = ``rotation.y``)."""
    agent = _agent(record)
    try:
        x, z = float(agent["position"]["x"]), float(agent["position"]["z"])
        yaw = float(agent["rotation"]["y"]) % 360.0
    except (TypeError, KeyError, ValueError):
        raise AdaptenvError(f"{where}: needs \"agent\" with position {{x, y, z}} and rotation {{x, y, z}} "
                            "(controller.last_event.metadata[\"agent\"])") from None
    if not all(math.isfinite(v) for v in (x, z, yaw)):
        raise AdaptenvError(f"{where}: the agent's position or rotation is not a finite number")
    return Pose(x=x, z=z, yaw=yaw)


def _success(record: dict[str, Any]) -> bool | None:
    ok = record.get("lastActionSuccess", (record.get("metadata") or {}).get("lastActionSuccess"))
    return ok if isinstance(ok, bool) else None


def action_code(action: Any, before: Pose, after: Pose, where: str) -> str | None:
    """adaptenv's code (``spec.ACTIONS``) for a logged action, or None for one that does not move the agent."""
    args: dict[str, Any] = {}
    if isinstance(action, dict):
        action, args = action.get("action"), action
    if not isinstance(action, str):
        raise AdaptenvError(f"{where}: \"action\" must be an action name or the dict given to controller.step")
    if action in NO_FLOOR_MOTION:
        return None
    if action == "MoveAgent":
        ahead = args.get("ahead")
        if not isinstance(ahead, (int, float)) or ahead == 0:
            raise AdaptenvError(f"{where}: MoveAgent needs a non-zero \"ahead\" (log the dict given to controller.step)")
        return "m" if ahead > 0 else "b"
    if action == "RotateAgent":
        degrees = args.get("degrees")
        if not isinstance(degrees, (int, float)) or degrees == 0:
            raise AdaptenvError(f"{where}: RotateAgent needs a non-zero \"degrees\" (log the dict given to "
                                "controller.step)")
        return ("r" if degrees > 0 else "l") + ("s" if abs(degrees) < SMALL_TURN_BELOW else "")
    code = _NAMES.get(action)
    if code is None:
        known = sorted({*_NAMES, "MoveAgent", "RotateAgent"})
        raise AdaptenvError(f"{where}: unknown action {action!r}; use one of {', '.join(known)}, or one that "
                            f"does not move the agent ({', '.join(sorted(NO_FLOOR_MOTION)[:4])}, ...)")
    turn = (after.yaw - before.yaw + 180.0) % 360.0 - 180.0
    if code in ("l", "r") and 0 < abs(turn) < SMALL_TURN_BELOW:
        code += "s"  # RotateLeft/Right with a small "degrees"
    return code


def resolve_target(name: str, where: str) -> str:
    """The ObjectNav target type a logged name denotes (a type or a WordNet synset such as ``bed.n.01``)."""
    t = type_for_name(name)
    if t not in TARGET_TYPES:
        raise AdaptenvError(f"{where}: target {name!r} is not one of adaptenv's ObjectNav targets "
                            f"({', '.join(TARGET_TYPES)}); give \"target_type\" in the header or --target")
    return t


def trajectory_from_ai2thor(records: Sequence[dict[str, Any]], world: NavWorld, target_type: str, *,
                            house: str | None = None, policy: str = "ai2thor", seed: int | None = None,
                            source: str = "log", lines: Sequence[int] | None = None) -> Conversion:
    """The adaptenv trajectory of one AI2-THOR episode in ``world`` (see the module docstring).

    ``records`` are the logged events, the start first; ``source`` and ``lines`` (each record's line
    number) only place errors ("LOG line N: ...").
    """
    lines = list(lines) if lines is not None else list(range(1, len(records) + 1))
    if not records:
        raise AdaptenvError(f"{source}: no event records; log the start and every step (docs/simulator.md)")
    target = resolve_target(target_type, source)
    if not world.instances_of(target):
        raise AdaptenvError(f"{source}: house {world.name} has no {target}; convert the log with the house the "
                            f"episode ran in")
    floor = world.geometry.floor
    poses: list[Pose] = []
    for k, rec in enumerate(records):
        where = f"{source} line {lines[k]}"
        pose = _pose(rec, where)
        if floor.distance(shapely.Point(pose.x, pose.z)) > OUTSIDE_TOLERANCE:
            raise AdaptenvError(f"{where}: the agent at ({metres(pose.x)}, {metres(pose.z)}) m is outside every room of house "
                                f"{world.name}; convert the log with the house the episode ran in")
        poses.append(pose)
    steps: list[Step] = []
    dropped: Counter = Counter()
    along: list[float] = []
    for k in range(1, len(records)):
        where = f"{source} line {lines[k]}"
        if steps and steps[-1].action == "end":
            raise AdaptenvError(f"{where}: an event after the episode's end action; log one episode per file")
        action = records[k].get("action")
        if (why := step_jump(poses[k - 1], poses[k])) is not None:
            raise AdaptenvError(f"{where}: {why}; log every step of one episode (AI2-THOR with gridSize 0.2 and "
                                "rotateStepDegrees 30, as SPOC runs it)")
        code = action_code(action, poses[k - 1], poses[k], where)
        if code is None:
            dropped[action["action"] if isinstance(action, dict) else action] += 1
            continue
        step = Step(pose=poses[k - 1], action=code, moved=_moved(code, records[k], poses[k - 1], poses[k]))
        record_sight(world, target, step)
        steps.append(step)
        if code in ("m", "b") and (c := _along_heading(poses[k - 1], poses[k], code)) is not None:
            along.append(c)
    if along and float(np.median(along)) < MIN_ALONG_HEADING:
        raise AdaptenvError(f"{source}: the agent's moves do not go where rotation.y faces (median cosine "
                            f"{float(np.median(along)):.2f}); log AI2-THOR's own metadata[\"agent\"] (yaw in degrees, "
                            "0 facing +z, 90 facing +x)")
    traj = Trajectory(house=house or world.name, target_type=target, **target_fields(world, target),
                      start=poses[0], steps=steps, final_pose=poses[-1], policy=policy, seed=seed)
    if (why := pose_jumps(traj)) is not None:  # a move whose lastActionSuccess its poses contradict
        raise AdaptenvError(f"{source}: {why}; log lastActionSuccess as AI2-THOR reports it")
    traj.metrics = episode_metrics(world, traj)
    return Conversion(traj, dropped)


def _along_heading(before: Pose, after: Pose, code: str) -> float | None:
    """Cosine between a move's displacement and the heading it should follow (None for no displacement)."""
    dx, dz = after.x - before.x, after.z - before.z
    d = math.hypot(dx, dz)
    if d < 1e-2:
        return None
    t = math.radians(before.yaw)
    return (dx * math.sin(t) + dz * math.cos(t)) / d * (1.0 if code == "m" else -1.0)


def _moved(code: str, record: dict[str, Any], before: Pose, after: Pose) -> bool:
    """Whether a move went through: AI2-THOR's lastActionSuccess, else whether the position changed."""
    if code not in ("m", "b"):
        return True
    ok = _success(record)
    return ok if ok is not None else math.hypot(after.x - before.x, after.z - before.z) > 1e-3


def convert_ai2thor_log(path: str | Path, world: NavWorld, *, target_type: str | None = None) -> Conversion:
    """Read an AI2-THOR log and convert it in ``world``; ``target_type`` overrides the header's."""
    log = read_ai2thor_log(path)
    target = target_type or log.header.get("target_type")
    if not isinstance(target, str):
        raise AdaptenvError(f"{log.source}: no target type; put \"target_type\" in the log's header line or pass "
                            "--target")
    house, seed = log.header.get("house"), log.header.get("seed")
    conversion = trajectory_from_ai2thor(log.records, world, target, house=None if house is None else str(house),
                                   policy=str(log.header.get("policy", "ai2thor")),
                                   seed=seed if isinstance(seed, int) else None, source=log.source, lines=log.lines)
    if (why := conversion.trajectory.problem()) is not None:
        raise AdaptenvError(f"{log.source}: the converted episode is not one, at {why}; log at least one action "
                            "that moves or turns the agent")
    return conversion


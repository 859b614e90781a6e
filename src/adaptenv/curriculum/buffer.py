"""The level buffer of PLR-robust and ACCEL, as data plus pure functions (JaxUED style).

A :class:`LevelBufferState` holds only level ids and numbers (the closed loop keeps the houses
themselves on disk or in a dict keyed by id); every function takes a state and returns a new one,
never mutating its input, so a state can be checkpointed as JSON and a run replayed from it.
``t`` is the caller's clock (e.g. the number of episodes so far); it only has to increase.

The loop these functions serve (see docs/curriculum-building-blocks.md):

1. ``should_replay(state, cfg, rng)``: once the buffer is ``min_fill`` full, replay with
   probability ``replay_prob``.
2. Replay: ``idxs = sample_replay(state, cfg, rng, t, k)`` draws buffer levels only, from
   ``replay_distribution`` (rank prioritisation mixed with staleness); train on them, then
   ``update_scores(state, idxs, new_scores, t)``. ACCEL: ``select_parents(state, idxs, rng)``
   plans one edited child per replayed level; score the children and ``insert_children``.
3. Otherwise: score a new level and ``insert`` it (it replaces the lowest-scored level when the
   buffer is full, and only if its score is higher).

Scores: :func:`regret_score` and friends (navigation's true regret, where the expert gives the
optimum).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Literal

import numpy as np

from adaptenv.agents.regret import spl_regret, success_regret
from adaptenv.configfile import STRICT, parse_config
from adaptenv.errors import ConfigError

ScoreName = Literal["regret", "spl_regret", "mixed"]
SCORE_NAMES: tuple[str, ...] = ("regret", "spl_regret", "mixed")
STATE_VERSION = 1


# --------------------------------------------------------------------------- config and state


@dataclass(frozen=True)
class LevelBufferConfig:
    """Hyperparameters of the level buffer (defaults after Robust PLR / ACCEL, smaller capacity)."""

    capacity: int = 1000
    """Most levels kept (dcd/jaxued use 4,000; our levels are far more expensive to make)."""
    temperature: float = 0.3
    """Rank temperature T of P ~ (1/rank)^(1/T); lower concentrates replay on the top levels."""
    staleness_coef: float = 0.3
    """Weight of the staleness distribution in the replay mixture (0.3-0.5 in the papers)."""
    replay_prob: float = 0.5
    """Probability of replaying a buffer level instead of trying a new one (0.5-0.8)."""
    min_fill: float = 0.5
    """Fraction of ``capacity`` that must be filled before any replay happens."""
    score: ScoreName = "regret"
    """Level score: regret (expert - agent success), spl_regret (1 - SPL), or mixed (their mean)."""

    def check(self) -> LevelBufferConfig:
        """Return self, or raise ConfigError naming the first out-of-range field and its range."""
        def bad(name: str, want: str) -> ConfigError:
            return ConfigError(f"level buffer config: {name} must be {want}, got {getattr(self, name)!r}")

        if isinstance(self.capacity, bool) or not isinstance(self.capacity, int) or self.capacity < 1:
            raise bad("capacity", "a positive integer")
        if not (math.isfinite(self.temperature) and self.temperature > 0):
            raise bad("temperature", "a positive number (about 0.3)")
        if not 0.0 <= self.staleness_coef <= 1.0:
            raise bad("staleness_coef", "between 0 and 1")
        if not 0.0 <= self.replay_prob <= 1.0:
            raise bad("replay_prob", "between 0 and 1")
        if not 0.0 <= self.min_fill <= 1.0:
            raise bad("min_fill", "between 0 and 1")
        if self.score not in SCORE_NAMES:
            raise bad("score", f"one of {', '.join(SCORE_NAMES)}")
        return self

    @property
    def min_size(self) -> int:
        """Levels needed before replay may start (at least one)."""
        return max(1, math.ceil(self.min_fill * self.capacity - 1e-9))


@dataclass(frozen=True)
class LevelBufferState:
    """The buffer's contents: parallel tuples, one entry per level, in slot order.

    Slots keep their position until the level in them is replaced, so indices returned by
    :func:`sample_replay` stay valid until the next :func:`insert`.
    """

    level_ids: tuple[str, ...] = ()
    """Key of each level (the caller maps ids to houses)."""
    scores: tuple[float, ...] = ()
    """Latest score of each level (higher = more worth replaying)."""
    last_seen: tuple[int, ...] = ()
    """Clock ``t`` at which each level was last inserted, scored or replayed."""
    parent_ids: tuple[str | None, ...] = ()
    """The level each one was edited from (ACCEL children), None for new levels."""
    n_inserted: int = 0
    """How many levels were ever added (a counter; evicted and current ones alike)."""
    version: int = field(default=STATE_VERSION)
    """Format version of the JSON checkpoint."""

    __pydantic_config__ = STRICT

    @property
    def size(self) -> int:
        """Levels currently held."""
        return len(self.level_ids)

    def index(self, level_id: str) -> int | None:
        """Slot of ``level_id``, or None when it is not in the buffer."""
        try:
            return self.level_ids.index(level_id)
        except ValueError:
            return None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def to_json(self) -> str:
        """The state as one JSON document (for checkpoints)."""
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "level buffer state") -> LevelBufferState:
        """Rebuild a state from :meth:`to_dict` data, checking every field's type; ConfigError names the bad one."""
        if isinstance(data, dict) and data.get("version", STATE_VERSION) != STATE_VERSION:
            raise ConfigError(f"{source}: version {data['version']!r} is not supported (expected {STATE_VERSION}); "
                              "re-create the buffer with this adaptenv version")
        state = parse_config(cls, data, source, fix="restore the checkpoint file (written by LevelBufferState.to_json)")
        problem = state_problem(state)
        if problem:
            raise ConfigError(f"{source}: {problem}")
        return state

    @classmethod
    def from_json(cls, text: str, source: str = "level buffer state") -> LevelBufferState:
        """Parse :meth:`to_json` output (``source`` names the file in errors)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{source}: not valid JSON ({exc}); restore the checkpoint file") from exc
        return cls.from_dict(data, source)


LEVEL_ID_MAX = 200
"""The longest level id: a level is stored as ``<id>.json`` in its run folder, and file names stop at 255 bytes."""


def level_id_problem(level_id: object) -> str | None:
    """Why ``level_id`` is not a plain name of a level inside its run folder (a file name, no folder part), or None."""
    if (isinstance(level_id, str) and level_id not in ("", ".", "..") and not set(level_id) & {"/", "\\", "\0"}
            and len(level_id.encode("utf-8", "surrogatepass")) <= LEVEL_ID_MAX):
        return None
    return (f"level id {level_id!r} is not a plain name of a level inside the run folder (a file name such as "
            f"house_00~t01a00, no folder part, at most {LEVEL_ID_MAX} bytes)")


def state_problem(state: LevelBufferState) -> str | None:
    """The first inconsistency of a state (unequal lengths, duplicate ids, an id that is not a plain name, bad
    numbers), or None."""
    n = len(state.level_ids)
    for level_id in (*state.level_ids, *(p for p in state.parent_ids if p is not None)):
        if (problem := level_id_problem(level_id)) is not None:
            return problem
    for name in ("scores", "last_seen", "parent_ids"):
        if len(getattr(state, name)) != n:
            return f"{name} has {len(getattr(state, name))} entries but level_ids has {n}; the lists must align"
    if len(set(state.level_ids)) != n:
        return "level_ids contains a duplicate id; every level may appear once"
    if not all(math.isfinite(s) for s in state.scores):
        return "scores contains a non-finite value; scores must be finite numbers"
    if state.n_inserted < n:
        return f"n_inserted ({state.n_inserted}) is smaller than the number of levels ({n})"
    return None


def empty_state() -> LevelBufferState:
    """A buffer holding no level."""
    return LevelBufferState()


# --------------------------------------------------------------------------- updates


def _finite(score: float, what: str = "score") -> float:
    value = float(score)
    if not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number, got {score!r}")
    return value


def _set(values: tuple, i: int, value: Any) -> tuple:
    return values[:i] + (value,) + values[i + 1:]


def lowest_slot(state: LevelBufferState) -> int:
    """The slot an insertion would replace: lowest score, then stalest (smallest last_seen), then first."""
    if state.size == 0:
        raise ValueError("the level buffer is empty")
    return min(range(state.size), key=lambda i: (state.scores[i], state.last_seen[i], i))


def insert(state: LevelBufferState, cfg: LevelBufferConfig, level_id: str, score: float, t: int,
           parent_id: str | None = None) -> LevelBufferState:
    """Add a scored level; when full it replaces the lowest-scored one, and only if ``score`` is higher.

    A level already in the buffer just gets the new score and ``last_seen = t``. Ids that are in
    ``state`` but not in the result were evicted (see :func:`dropped_ids`) and can be deleted.
    """
    score = _finite(score)
    i = state.index(level_id)
    if i is not None:
        return replace(state, scores=_set(state.scores, i, score), last_seen=_set(state.last_seen, i, int(t)))
    if state.size < cfg.capacity:
        return replace(state, level_ids=state.level_ids + (level_id,), scores=state.scores + (score,),
                       last_seen=state.last_seen + (int(t),), parent_ids=state.parent_ids + (parent_id,),
                       n_inserted=state.n_inserted + 1)
    j = lowest_slot(state)
    if score <= state.scores[j]:
        return state
    return replace(state, level_ids=_set(state.level_ids, j, level_id), scores=_set(state.scores, j, score),
                   last_seen=_set(state.last_seen, j, int(t)), parent_ids=_set(state.parent_ids, j, parent_id),
                   n_inserted=state.n_inserted + 1)


def dropped_ids(before: LevelBufferState, after: LevelBufferState) -> list[str]:
    """Ids held ``before`` and not ``after`` (evicted levels whose houses can be deleted)."""
    kept = set(after.level_ids)
    return [x for x in before.level_ids if x not in kept]


def update_scores(state: LevelBufferState, idxs: Sequence[int], scores: Sequence[float], t: int) -> LevelBufferState:
    """New scores for the levels in slots ``idxs`` (just replayed), and ``last_seen = t`` for them.

    A slot listed twice takes its last score.
    """
    idxs = [int(i) for i in idxs]
    if len(idxs) != len(scores):
        raise ValueError(f"update_scores: {len(idxs)} slots but {len(scores)} scores; pass one score per slot")
    new_scores, new_seen = list(state.scores), list(state.last_seen)
    for i, s in zip(idxs, scores, strict=True):
        if not 0 <= i < state.size:
            raise IndexError(f"update_scores: slot {i} is outside the buffer (size {state.size})")
        new_scores[i] = _finite(s)
        new_seen[i] = int(t)
    return replace(state, scores=tuple(new_scores), last_seen=tuple(new_seen))


# --------------------------------------------------------------------------- replay


def rank_weights(scores: np.ndarray, temperature: float) -> np.ndarray:
    """Rank prioritisation h = (1/rank)^(1/T), normalised; rank 1 is the highest score, ties share the best rank."""
    desc = np.sort(-scores)
    rank = np.searchsorted(desc, -scores, side="left") + 1.0
    h = np.exp(-np.log(rank) / temperature)  # (1/rank)^(1/T) without overflow for small T
    return h / h.sum()


def staleness_weights(last_seen: np.ndarray, t: int) -> np.ndarray:
    """Staleness P_C = (t - last_seen) / sum(t - last_seen); uniform when every level was just seen."""
    stale = float(t) - last_seen
    if np.any(stale < 0):
        raise ValueError(f"replay_distribution: t={t} is earlier than a level's last_seen ({int(last_seen.max())}); "
                         "t must be the current clock")
    total = stale.sum()
    if total <= 0:
        return np.full(len(stale), 1.0 / len(stale))
    return stale / total


def replay_distribution(state: LevelBufferState, cfg: LevelBufferConfig, t: int) -> np.ndarray:
    """P = (1 - rho) * P_rank + rho * P_staleness over the buffer's slots (rho = ``staleness_coef``)."""
    if state.size == 0:
        raise ValueError("replay_distribution: the level buffer is empty; insert levels before replaying")
    p_rank = rank_weights(np.asarray(state.scores, dtype=np.float64), cfg.temperature)
    p_stale = staleness_weights(np.asarray(state.last_seen, dtype=np.float64), t)
    p = (1.0 - cfg.staleness_coef) * p_rank + cfg.staleness_coef * p_stale
    return p / p.sum()


def can_replay(state: LevelBufferState, cfg: LevelBufferConfig) -> bool:
    """True once the buffer holds ``min_fill * capacity`` levels (never when empty)."""
    return state.size >= cfg.min_size


def should_replay(state: LevelBufferState, cfg: LevelBufferConfig, rng: np.random.Generator) -> bool:
    """Replay now? False until the buffer is ``min_fill`` full, then True with ``replay_prob``.

    Always consumes exactly one draw of ``rng``, so the random stream does not depend on the fill.
    """
    u = float(rng.random())
    return can_replay(state, cfg) and u < cfg.replay_prob


def sample_replay(state: LevelBufferState, cfg: LevelBufferConfig, rng: np.random.Generator, t: int,
                  k: int = 1) -> np.ndarray:
    """``k`` buffer slots drawn independently from :func:`replay_distribution` (a level may repeat).

    Only levels in the buffer are ever returned: replay never falls back to new random levels.
    """
    if k < 1:
        raise ValueError(f"sample_replay: k must be at least 1, got {k}")
    p = replay_distribution(state, cfg, t)
    return rng.choice(state.size, size=k, replace=True, p=p).astype(np.int64)


# --------------------------------------------------------------------------- ACCEL


@dataclass(frozen=True)
class ChildPlan:
    """One ACCEL child to make: edit ``parent_id`` with ``seed`` and register it as ``child_id``."""

    parent_slot: int
    """Slot of the parent in the state the plan was made from."""
    parent_id: str
    child_id: str
    seed: int
    """Seed of the child's random edits (each child has its own)."""


def select_parents(state: LevelBufferState, idxs: Sequence[int], rng: np.random.Generator) -> list[ChildPlan]:
    """One child plan per replayed slot, in order: every replayed level gets its own edited child.

    A level replayed twice gets two children with different seeds. Child ids are
    ``"<parent>~<seed hex>"``; lineage is kept in the buffer's ``parent_ids``.
    """
    plans = []
    for i in (int(i) for i in idxs):
        if not 0 <= i < state.size:
            raise IndexError(f"select_parents: slot {i} is outside the buffer (size {state.size})")
        seed = int(rng.integers(2**63 - 1))
        parent = state.level_ids[i]
        plans.append(ChildPlan(parent_slot=i, parent_id=parent, child_id=f"{parent.split('~')[0]}~{seed:016x}",
                               seed=seed))
    return plans


def insert_children(state: LevelBufferState, cfg: LevelBufferConfig, plans: Sequence[ChildPlan],
                    scores: Sequence[float], t: int) -> LevelBufferState:
    """Insert each scored child with its parent id (a child of no score, None, was invalid and is skipped)."""
    if len(plans) != len(scores):
        raise ValueError(f"insert_children: {len(plans)} children but {len(scores)} scores")
    for plan, score in zip(plans, scores, strict=True):
        if score is not None:
            state = insert(state, cfg, plan.child_id, score, t, parent_id=plan.parent_id)
    return state


# --------------------------------------------------------------------------- scores


def regret_score(agent_success: float | Sequence[float], agent_spl: float | Sequence[float],
                 expert_success: float | Sequence[float], kind: ScoreName = "regret") -> float:
    """A level's score from its episodes (one value per episode, or scalars for one episode).

    ``regret``: expert success minus agent success; ``spl_regret``: 1 - SPL on solvable episodes;
    ``mixed``: their mean. Levels the expert cannot solve score 0, so they are not prioritised.
    """
    if kind == "regret":
        return success_regret(agent_success, expert_success)
    if kind == "spl_regret":
        return spl_regret(agent_spl, expert_success)
    if kind == "mixed":
        return 0.5 * (success_regret(agent_success, expert_success) + spl_regret(agent_spl, expert_success))
    raise ValueError(f"regret_score: kind must be one of {', '.join(SCORE_NAMES)}, got {kind!r}")


__all__ = [
    "SCORE_NAMES", "ChildPlan", "LevelBufferConfig", "LevelBufferState", "ScoreName", "can_replay", "dropped_ids",
    "empty_state", "insert", "insert_children", "lowest_slot", "rank_weights", "regret_score", "replay_distribution",
    "sample_replay", "select_parents", "should_replay", "spl_regret", "staleness_weights", "state_problem",
    "success_regret", "update_scores",
]

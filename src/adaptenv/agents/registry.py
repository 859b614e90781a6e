"""Turn a ``--policy`` value into a policy: ``pretrained``, ``expert``, ``random``, a checkpoint, or code.

Accepted specs (every command taking ``--policy`` uses :func:`resolve_policy`):

- ``pretrained``: the strongest checkpoint shipped in the package, the map-reading agent after
  anchored PPO (``adaptenv/agents/data/pretrained-ppo.pt``; ``pretrained-ppo`` names the same file).
- ``pretrained-map``: the map-reading checkpoint taught by the map explorer, before PPO;
  ``pretrained-scan``: the scan-only agent, which cannot search (docs/agent.md has their cards).
- ``expert``: the shortest-path expert (privileged).
- ``explorer``: frontier exploration on the agent's own map, then the shortest path to a sighted
  target (knows its pose, not the target's location; :mod:`adaptenv.agents.explorer`).
- ``map-explorer``: the same search planned on the agent's own EgoMap only (no privileged
  information; :mod:`adaptenv.agents.map_explorer`).
- ``random`` or ``random:SEED``: uniformly random actions.
- ``scratch`` / ``scratch-shape``: a freshly initialised map-reading network (``adaptenv train``'s default sizes
  with ``--map``), its weights drawn from the seed; ``scratch`` is told the classes of what its rays hit,
  ``scratch-shape`` perceives shapes only (the recognising mode, ``--perception shape``). What ``adaptenv loop``
  starts from to learn from scratch (docs/curriculum.md).
- a path to a checkpoint file (``*.pt``) written by ``adaptenv train``.
- ``module:attribute`` or ``path/to/file.py:attribute``: user code. The attribute may be a policy
  object, a policy class, or a zero-argument factory returning a policy.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
from importlib import resources
from pathlib import Path

import numpy as np

from adaptenv.agents.config import TrainConfig
from adaptenv.agents.explorer import ExplorerPolicy
from adaptenv.agents.map_explorer import MapExplorerPolicy
from adaptenv.agents.policy import ExpertPolicy, Policy, RandomPolicy
from adaptenv.configfile import printable
from adaptenv.errors import ConfigError, PolicyError
from adaptenv.sim.spec import ACTIONS, N_ACTIONS

SHIPPED_FILES = {"pretrained": "pretrained-ppo", "pretrained-ppo": "pretrained-ppo", "pretrained-map": "pretrained-map",
                 "pretrained-scan": "pretrained-scan"}
"""Shipped checkpoint names -> their file stem in ``adaptenv/agents/data``: ``pretrained`` is the strongest
(the map-reading agent after anchored PPO), then it before PPO, then the scan-only agent (docs/agent.md)."""
SHIPPED = tuple(SHIPPED_FILES)
SCRATCH = {"scratch": "labels", "scratch-shape": "shape"}
"""Fresh map-reading networks by name -> their perception (``TrainConfig.perception``)."""
BUILTINS = (*SHIPPED, "expert", "explorer", "map-explorer", "random", *SCRATCH)
_HELP = ("expected pretrained, pretrained-map, pretrained-scan, expert, explorer, map-explorer, random, scratch, "
         "scratch-shape, a checkpoint path (.pt) or module:attribute (e.g. examples/my_policy.py:policy)")
POLICY_HELP = ("Policy: pretrained (the strongest shipped agent), pretrained-map, pretrained-scan, expert, explorer, "
               "map-explorer, random, scratch or scratch-shape (fresh weights), a checkpoint path (.pt), or "
               "module:attribute.")


def pretrained_path(name: str = "pretrained") -> Path:
    """Where the shipped checkpoint ``name`` (one of SHIPPED) lives inside the installed package."""
    return Path(str(resources.files("adaptenv.agents") / "data" / f"{SHIPPED_FILES[name]}.pt"))


def weights_record(spec: str) -> dict[str, str] | None:
    """Which weights a ``--policy`` spec runs: name, file and sha256 (None for a policy without a checkpoint)."""
    spec = spec.strip()
    path = pretrained_path(spec) if spec in SHIPPED else Path(spec)
    if not (spec in SHIPPED or path.suffix in (".pt", ".pth")) or not path.is_file():
        return None
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return {"name": spec, "file": path.name, "sha256": digest}


def load_pretrained(name: str = "pretrained", *, greedy: bool = False, seed: int = 0) -> Policy:
    """A shipped pretrained policy; a missing file names the command that creates it."""
    # torch: only when a checkpoint is loaded
    from adaptenv.agents.checkpoint import load_checkpoint

    path = pretrained_path(name)
    if not path.is_file():
        raise ConfigError(f"{path}: the {name} checkpoint is not installed; create it with the command of its card "
                          f"in docs/agent.md and -o src/adaptenv/agents/data/{name}.pt")
    policy = load_checkpoint(path).policy(greedy=greedy, seed=seed)
    policy.name = name
    return policy


def scratch_policy(perception: str = "labels", *, seed: int = 0) -> Policy:
    """A freshly initialised map-reading policy (``adaptenv train --map``'s sizes) in ``perception`` mode (labels or
    shape), its weights drawn from ``seed`` (torch's global generator is left as it was)."""
    # torch: only when a network is built
    import torch

    from adaptenv.agents.network import NavNet, NetConfig, NeuralPolicy

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = NavNet(NetConfig.of(TrainConfig(map=True, perception=perception)))
    name = next(k for k, v in SCRATCH.items() if v == perception)
    return NeuralPolicy(net, seed=seed, name=name)


def init_checkpoint(spec: str, *, flag: str = "--init") -> Path:
    """The checkpoint a warm start (``--init``) names: a SHIPPED name for a shipped one, else a path.

    The other ``--policy`` names (expert, explorer, map-explorer, random, scratch, module:attribute) have no
    checkpoint to start from and raise ConfigError (``adaptenv train`` starts from fresh weights without ``--init``).
    """
    spec = spec.strip()
    if spec in SHIPPED:
        return pretrained_path(spec)
    if spec in BUILTINS or spec.startswith("random:") or (":" in spec and Path(spec).suffix not in (".pt", ".pth")):
        raise ConfigError(f"{flag} {spec!r}: no network to start from; use pretrained or a checkpoint path (.pt)")
    return Path(spec)


def resolve_policy(spec: str, *, seed: int = 0) -> Policy:
    """Build the policy named by ``spec`` (see the module docstring); unknown specs raise ConfigError."""
    spec = spec.strip()
    if spec in SHIPPED:
        return load_pretrained(spec, seed=seed)
    if spec == "expert":
        return ExpertPolicy()
    if spec == "explorer":
        return ExplorerPolicy()
    if spec == "map-explorer":
        return MapExplorerPolicy()
    if spec in SCRATCH:
        return scratch_policy(SCRATCH[spec], seed=seed)
    if spec == "random" or spec.startswith("random:"):
        tail = spec.partition(":")[2]
        if tail and not tail.isdigit():
            raise ConfigError(f"--policy {spec!r}: the random seed must be an integer, e.g. random:3")
        return RandomPolicy(seed=int(tail) if tail else seed)
    path = Path(spec)
    if path.suffix in (".pt", ".pth") or (path.is_file() and ":" not in spec):
        # torch: only when a checkpoint is loaded
        from adaptenv.agents.checkpoint import load_checkpoint

        return load_checkpoint(path).policy(seed=seed)
    if ":" in spec:
        return _load_user_policy(spec)
    raise ConfigError(f"--policy {spec!r}: unknown policy; {_HELP}")


def _load_user_policy(spec: str) -> Policy:
    """Import ``module:attribute`` (or ``file.py:attribute``) and make a policy of it."""
    target, _, attr = spec.rpartition(":")
    if not target or not attr:
        raise ConfigError(f"--policy {spec!r}: unknown policy; {_HELP}")
    if target.endswith(".py"):
        file = Path(target)
        if not file.is_file():
            raise ConfigError(f"--policy {spec!r}: no such file {file}; check the path")
        name = f"adaptenv_user_policy_{abs(hash(str(file.resolve())))}"
        module_spec = importlib.util.spec_from_file_location(name, file)
        if module_spec is None or module_spec.loader is None:
            raise ConfigError(f"--policy {spec!r}: cannot import {file} as a Python module")
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        module_spec.loader.exec_module(module)
    else:
        try:
            module = importlib.import_module(target)
        except ImportError as exc:
            raise ConfigError(f"--policy {spec!r}: cannot import module {target!r} ({exc}); "
                              "check it is on PYTHONPATH or pass a file path like my_policy.py:policy") from None
    if not hasattr(module, attr):
        raise ConfigError(f"--policy {spec!r}: module {target!r} has no attribute {attr!r}")
    obj = getattr(module, attr)
    if isinstance(obj, type) or (callable(obj) and not isinstance(obj, Policy)):
        obj = obj()
    if not isinstance(obj, Policy):
        raise ConfigError(f"--policy {spec!r}: {attr!r} is not a policy; it needs initial_state(batch) "
                          "and act(obs, state, done) (see docs/agent.md)")
    return obj if type(obj).__module__.startswith("adaptenv.") else CheckedPolicy(obj, spec)


class CheckedPolicy:
    """A user's policy whose every answer is checked against the contract: ``act`` returns ``(actions, state)``
    with one whole-number action in ``range(N_ACTIONS)`` per episode it was given; anything else is one
    :class:`~adaptenv.errors.PolicyError` line naming the policy, the episode (counted from 0 in the order the
    episodes began) and the value. Every other attribute is the policy's own."""

    def __init__(self, policy: Policy, spec: str):
        self.policy, self.spec = policy, spec
        self._episode = np.zeros(0, dtype=np.int64)
        self._begun = 0

    def __getattr__(self, name: str):
        if name.startswith("_") or name in ("policy", "spec"):  # unpickling looks these up before __init__ ran
            raise AttributeError(name)
        return getattr(self.policy, name)

    def initial_state(self, batch: int):
        return self.policy.initial_state(batch)

    def act(self, obs, state, done: np.ndarray):
        done = np.asarray(done, dtype=bool).reshape(-1)
        self._count(done)
        out = self.policy.act(obs, state, done)
        if not isinstance(out, (tuple, list)) or len(out) != 2:
            raise PolicyError(f"--policy {printable(self.spec)}: act() returned {type(out).__name__}, not the pair "
                              "(actions, state); fix its act() (see docs/agent.md)")
        actions, new_state = out
        return contract_actions(actions, self._episode, self.spec), new_state

    def _count(self, done: np.ndarray) -> None:
        """Number the episodes in the order they begin (``done`` marks a slot's first observation)."""
        if len(self._episode) != len(done):
            self._episode = np.full(len(done), -1, dtype=np.int64)
            done = np.ones(len(done), dtype=bool) if not done.any() else done
        for i in np.flatnonzero(done):
            self._episode[i] = self._begun
            self._begun += 1


def contract_actions(actions, episodes: np.ndarray, spec: str) -> np.ndarray:
    """``actions`` as int64 when they are one whole number in ``range(N_ACTIONS)`` per episode of ``episodes`` (the
    episode number of each slot), else a PolicyError naming the policy ``spec``, the episode and the value."""
    who = f"--policy {printable(spec)}"
    try:
        a = np.asarray(actions)
    except (TypeError, ValueError):
        a = np.asarray([actions], dtype=object)
    if a.ndim != 1 or len(a) != len(episodes):
        count = a.shape[0] if a.ndim == 1 else a.size
        raise PolicyError(f"{who} returned {count} action{'s' if count != 1 else ''} for {len(episodes)} "
                          f"episode{'s' if len(episodes) != 1 else ''}; act() returns one action per episode it is "
                          "given (shape (B,)); fix its act()")
    for i, value in enumerate(a.tolist()):
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and float(value).is_integer()
              and 0 <= value < N_ACTIONS)
        if not ok:
            shown = printable(repr(value))[:40]
            raise PolicyError(f"{who} returned action {shown} in episode {int(episodes[i])}; an action is a whole "
                              f"number from 0 to {N_ACTIONS - 1} ({', '.join(ACTIONS)}); fix its act()")
    return a.astype(np.int64)

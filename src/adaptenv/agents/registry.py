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

from adaptenv.agents.config import TrainConfig
from adaptenv.agents.explorer import ExplorerPolicy
from adaptenv.agents.map_explorer import MapExplorerPolicy
from adaptenv.agents.policy import ExpertPolicy, Policy, RandomPolicy
from adaptenv.errors import ConfigError

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
    return obj

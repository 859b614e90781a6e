"""Register adaptenv's Gymnasium ids as soon as both adaptenv and gymnasium are imported, in either order.

``import adaptenv`` must make ``gymnasium.make("adaptenv/ObjectNav-v0")`` work, but importing
gymnasium costs about a quarter of a second, which ``adaptenv --help`` and scripts that never make
an env should not pay. So: if gymnasium is already imported, register now; otherwise put a finder
on ``sys.meta_path`` that lets gymnasium load normally and registers right after it has loaded.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
from types import ModuleType


def register_envs() -> None:
    """Register the ids (importing :mod:`adaptenv.sim` does it; it is idempotent)."""
    importlib.import_module("adaptenv.sim")


class _RegisterAfterLoad(importlib.abc.Loader):
    """Runs gymnasium's own loader, then registers adaptenv's ids."""

    def __init__(self, loader: importlib.abc.Loader):
        self.loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self.loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self.loader.exec_module(module)
        register_envs()


class _GymnasiumWatcher(importlib.abc.MetaPathFinder):
    """Finds gymnasium with the other finders and wraps its loader; removes itself after one use."""

    def find_spec(self, name: str, path=None, target=None) -> importlib.machinery.ModuleSpec | None:
        if name != "gymnasium":
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is not None and spec.loader is not None:
            spec.loader = _RegisterAfterLoad(spec.loader)
        return spec


def install() -> None:
    """Register now if gymnasium is loaded, else as soon as it is."""
    if "gymnasium" in sys.modules:
        register_envs()
    elif not any(isinstance(f, _GymnasiumWatcher) for f in sys.meta_path):
        sys.meta_path.insert(0, _GymnasiumWatcher())

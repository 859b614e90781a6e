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
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import gymnasium


def register_envs() -> None:
    """Register the ids (idempotent)."""
    import gymnasium  # loaded by now: this runs only once gymnasium is imported

    from adaptenv.sim import OBJECTNAV_ID

    if OBJECTNAV_ID not in gymnasium.registry:
        gymnasium.register(id=OBJECTNAV_ID, entry_point="adaptenv._gym:objectnav_env",
                           vector_entry_point="adaptenv.sim.env:NavVectorEnv", disable_env_checker=False)


def objectnav_env(**kwargs) -> gymnasium.Env:
    """``adaptenv/ObjectNav-v0``: a :class:`~adaptenv.sim.env.NavEnv` that renders with the top-down renderer."""
    from adaptenv.render.topdown import (
        env_frame,  # the simulator and renderer load only when an env is made
    )
    from adaptenv.sim.env import NavEnv

    if kwargs.get("render_mode") is not None:
        kwargs.setdefault("renderer", env_frame)
    return NavEnv(**kwargs)


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

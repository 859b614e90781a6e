"""adaptenv: closed-loop, adaptive environment generation for embodied navigation agents.

The public API is small and imported lazily so that `import adaptenv` stays fast:

>>> from adaptenv import load_house, save_house

``import adaptenv`` also registers the Gymnasium id ``adaptenv/ObjectNav-v0`` (when gymnasium is
imported, before or after adaptenv; see :mod:`adaptenv._gym`), and makes sure numba has a writable
cache folder for its compiled kernels (:mod:`adaptenv._numba_cache`).
"""

from __future__ import annotations

import importlib
from typing import Any

from adaptenv import _gym, _numba_cache

__version__ = "0.1.0"

_EXPORTS = {
    "House": "adaptenv.scene.house",
    "load_house": "adaptenv.scene.house",
    "save_house": "adaptenv.scene.house",
    "validate_house": "adaptenv.scene.validate",
    "AssetCatalog": "adaptenv.scene.assets",
    "load_catalog": "adaptenv.scene.assets",
    "SceneGeometry": "adaptenv.scene.geometry",
    "NormalizedGrid": "adaptenv.scene.grid",
    "generate_house": "adaptenv.scene.procedural",
    "generate_houses": "adaptenv.scene.procedural",
    "rearrange_house": "adaptenv.scene.procedural",
    "render_house": "adaptenv.render.topdown",
    "AdaptenvError": "adaptenv.errors",
    "HouseError": "adaptenv.errors",
}

__all__ = sorted(_EXPORTS) + ["__version__"]

_gym.install()
_numba_cache.configure()  # before any numba kernel is defined


def __getattr__(name: str) -> Any:
    """Import public names on first use (PEP 562)."""
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'adaptenv' has no attribute {name!r}")

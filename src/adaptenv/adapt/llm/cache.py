"""Response cache: one JSON file per distinct request, so re-runs are free and reproducible.

The key is the SHA-256 of the canonical JSON of everything that shapes the answer (provider,
base URL, model, sampling settings, system prompt, every turn with its image hash, and the tool or
schema). Files hold the parsed answer and its token usage, never the API key or image bytes.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: Bump when the record layout changes; old files then simply miss.
CACHE_FORMAT = 1


def request_key(payload: dict[str, Any]) -> str:
    """SHA-256 hex digest of the canonical JSON of ``payload`` (sorted keys, no whitespace)."""
    canonical = json.dumps({"format": CACHE_FORMAT, **payload}, sort_keys=True, separators=(",", ":"),
                           ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(canonical.encode("ascii")).hexdigest()


class ResponseCache:
    """JSON files under ``root/<key[:2]>/<key>.json``; unreadable entries count as misses."""

    def __init__(self, root: str | Path):
        self.root = Path(root)

    def path(self, key: str) -> Path:
        """Where the record of ``key`` lives."""
        return self.root / key[:2] / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        """The stored record, or None on a miss or a corrupt file."""
        path = self.path(key)
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, json.JSONDecodeError):
            log.warning("ignoring unreadable LLM cache file %s", path)
            return None
        if not isinstance(record, dict) or record.get("key") != key:
            log.warning("ignoring LLM cache file %s: it does not match its key", path)
            return None
        return record

    def put(self, key: str, record: dict[str, Any], *, secret: str | None = None) -> None:
        """Store ``record`` atomically; refuses (with a warning) to write anything containing ``secret``."""
        text = json.dumps({"key": key, **record}, sort_keys=True, indent=1, ensure_ascii=False)
        if secret and len(secret) >= 8 and secret in text:
            log.warning("not caching an LLM answer that contains the API key")
            return
        path = self.path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".json")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(text)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

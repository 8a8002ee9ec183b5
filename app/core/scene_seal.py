"""A scene's seal: the absolute paths a scene JSON names, signed with this user's key, so
a scene voxwarp saved reopens from anywhere while a scene from elsewhere cannot make
voxwarp read outside its folder.

Saving (:func:`seal_paths`): the sorted absolute path strings in the document are signed
with HMAC-SHA256 under a random 32-byte key kept in the user's configuration folder
(``$VOXWARP_CONFIG_DIR``, else ``$XDG_CONFIG_HOME/voxwarp``, else ``~/.config/voxwarp``;
the file ``scene-key``, mode 0600, created on first use). Loading (:func:`trust_sealed`):
when the seal matches, exactly those files are allowed for the rest of the process
(:func:`voxwarp.core.allowed_folders.allow_files`). An edited path, a scene written by
another user or machine, or no key: nothing is trusted, and the usual rule applies (the
scene's folder and the allowed folders).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from pathlib import Path
from typing import Any

from voxwarp.core.allowed_folders import allow_files

#: The scene JSON key holding the seal (hex HMAC-SHA256).
SEAL_KEY = "path_seal"
#: Environment variable naming voxwarp's configuration folder.
CONFIG_DIR_ENV = "VOXWARP_CONFIG_DIR"
_KEY_NAME = "scene-key"
_KEY_BYTES = 32


def config_dir() -> Path:
    """voxwarp's per-user configuration folder (it may not exist yet)."""
    env = os.environ.get(CONFIG_DIR_ENV)
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CONFIG_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".config") / "voxwarp"


def _read_key(path: Path) -> bytes | None:
    try:
        with open(path, "rb") as fh:
            key = fh.read(_KEY_BYTES + 1)
    except OSError:
        return None
    return key if len(key) == _KEY_BYTES else None


def _key(create: bool) -> bytes | None:
    """The user's key; with ``create``, made (mode 0600, exclusively) when missing.
    ``None`` when it cannot be read or made (a read-only home)."""
    path = config_dir() / _KEY_NAME
    key = _read_key(path)
    if key is not None or not create:
        return key
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:  # another process made it first
        return _read_key(path)
    except OSError:
        return None
    new = secrets.token_bytes(_KEY_BYTES)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(new)
    except OSError:
        path.unlink(missing_ok=True)
        return None
    return new


def absolute_paths(d: Any) -> list[str]:
    """The sorted distinct absolute path strings anywhere in a scene document (its seal
    left out)."""
    found: set[str] = set()
    stack = [d]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack.extend(v for k, v in item.items() if k != SEAL_KEY)
        elif isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, str) and len(item) < 4096 and os.path.isabs(item):
            found.add(item)
    return sorted(found)


def _mac(key: bytes, paths: list[str]) -> str:
    text = "\0".join(paths).encode("utf-8", "surrogatepass")
    return hmac.new(key, text, hashlib.sha256).hexdigest()


def seal_paths(d: dict[str, Any]) -> bool:
    """Add the seal of ``d``'s absolute paths to ``d`` (in place) when it names any;
    ``False`` when it names some but no key could be made (they stay unsealed)."""
    d.pop(SEAL_KEY, None)
    paths = absolute_paths(d)
    if not paths:
        return True
    key = _key(create=True)
    if key is None:
        return False
    d[SEAL_KEY] = _mac(key, paths)
    return True


def trust_sealed(d: Any) -> bool:
    """Allow the files a sealed scene document names when its seal is this user's;
    whether it was."""
    seal = d.get(SEAL_KEY) if isinstance(d, dict) else None
    if not isinstance(seal, str):
        return False
    key = _key(create=False)
    paths = absolute_paths(d)
    if key is None or not hmac.compare_digest(_mac(key, paths), seal):
        return False
    allow_files(paths)
    return True

"""Plugins of every kind (controller nodes, loop functions) are entry points: finding them by
name and importing them, with one clear error for a name that is unknown, declared twice or broken."""
from __future__ import annotations

from importlib.metadata import EntryPoint, entry_points
from typing import Callable


def installed(group: str, kind: str, error: Callable[[str], Exception]) -> dict[str, EntryPoint]:
    """Every entry point of ``group`` by name, sorted (nothing is imported); two distributions
    claiming one name is an ``error``. ``kind``: what they are, for the message."""
    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=group):
        other = found.get(ep.name)
        if other is not None and other.value != ep.value:
            raise error(f"{kind} {ep.name!r} is declared twice: by {_origin(other)} ({other.value}) "
                        f"and by {_origin(ep)} ({ep.value}); uninstall one")
        found[ep.name] = ep
    return dict(sorted(found.items()))


def load(group: str, name: str, kind: str, error: Callable[[str], Exception], unknown_hint: str = ""):
    """The object entry point ``name`` of ``group`` names, imported."""
    found = installed(group, kind, error)
    if name not in found:
        raise error(f"unknown {kind} {name!r} (installed: {', '.join(found) or 'none'}){unknown_hint}")
    ep = found[name]
    try:
        return ep.load()
    except Exception as e:  # any import-time failure is the plugin's, reported as such
        raise error(f"{kind} {name!r} ({ep.value}) failed to import: {type(e).__name__}: {e}") from e


def _origin(ep: EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    return f"package {dist.name}" if dist is not None else "an unknown package"

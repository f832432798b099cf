"""The entry type of trackmj's registries and how a registry is read: a name -> a one-line
description and a builder. Builders may be :func:`lazy`: named by module and function,
imported when first called, so that reading a registry's names (the CLI's choices, the
validators of scenario and sweep files) imports no MuJoCo, CasADi or numba. The structure
test counts a module named in a string as imported."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Entry:
    """One registered block: a one-line description, its builder, the names of the run
    products its builder needs besides the setup (mechanics: ``"tp_result"``, the tp run of
    the same case whose track load dp-a replays), and for a controller whether it is a
    baseline (``trackmj report`` runs the baselines beside each scenario's own controller
    for the controller claims)."""

    description: str
    build: Callable[..., Any]
    needs: tuple[str, ...] = ()
    baseline: bool = False


def lazy(module: str, name: str) -> Callable[..., Any]:
    """A builder that imports ``module`` and calls its ``name`` when first used."""

    def build(*args: Any, **kwargs: Any) -> Any:
        return getattr(importlib.import_module(module), name)(*args, **kwargs)

    build.__name__ = name
    return build


def choices(registry: dict[str, Any]) -> tuple[str, ...]:
    """The registered names, in registration order."""
    return tuple(registry)


def by_name(registry: dict[str, Entry]) -> tuple[str, ...]:
    """The names a file or option may give alone: entries whose builder needs nothing
    besides the run (the FMU controller needs its file: ``fmu:FILE.toml``)."""
    return tuple(name for name, entry in registry.items() if not entry.needs)

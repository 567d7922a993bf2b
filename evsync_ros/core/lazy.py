"""Imports put off until first use, so that a command loads only what it runs (``evsync restamp
--offsets`` needs no estimation engine, simulator or plots)."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

__all__ = ['exports', 'module']


def exports(package: str, names: Mapping[str, str]) -> Callable[[str], Any]:
    """A ``__getattr__`` for ``package`` (PEP 562) that gives each of ``names`` ({name: the module
    that defines it}) from its module, imported at first use, and keeps it."""

    def __getattr__(name: str) -> Any:
        try:
            where = names[name]
        except KeyError:
            raise AttributeError(f'module {package!r} has no attribute {name!r}') from None
        value = getattr(importlib.import_module(where), name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__


def module(name: str) -> ModuleType:
    """Module ``name``, executed at its first attribute's use (``importlib.util.LazyLoader``), or as
    it is when it is imported already."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        raise ModuleNotFoundError(f'no module named {name!r}', name=name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    found = importlib.util.module_from_spec(spec)
    sys.modules[name] = found
    loader.exec_module(found)
    parent, _, leaf = name.rpartition('.')
    if parent:  # as an import does: ``package.leaf`` is the module
        setattr(sys.modules[parent], leaf, found)
    return found

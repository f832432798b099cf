"""Find-or-raise access to the MJCF element tree (``xml.etree``): an element or attribute the
generator relies on that a model lacks is a ValueError naming it, not a None further on."""

from __future__ import annotations

import xml.etree.ElementTree as ET


def find(parent: ET.Element, path: str) -> ET.Element:
    """The first element at ``path`` (an ElementPath) below ``parent``; ValueError if none."""
    found = parent.find(path)
    if found is None:
        raise ValueError(f"the MJCF element <{parent.tag}> has no {path!r}")
    return found


def attribute(element: ET.Element, key: str) -> str:
    """The attribute ``key`` of ``element``; ValueError if it has none."""
    value = element.get(key)
    if value is None:
        raise ValueError(f"the MJCF element <{element.tag}> has no attribute {key!r}")
    return value

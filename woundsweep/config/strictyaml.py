"""YAML for sweep files: PyYAML's safe loader without aliases and without duplicate keys.

An alias lets a file of a few hundred bytes expand into gigabytes (each level of nested
aliases multiplies the document), and a duplicate key silently keeps only the last value;
neither has a use in a sweep file, so both are refused with the line they are on.
"""

from __future__ import annotations

from typing import Any

import yaml
from yaml.constructor import ConstructorError

__all__ = ["Refused", "load"]


class Refused(yaml.MarkedYAMLError):
    """A construct the sweep loader refuses (an alias, a duplicate key)."""


class _Loader(yaml.SafeLoader):
    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise Refused(
                None, None, f"YAML aliases (*{event.anchor}) are not accepted", event.start_mark
            )
        return super().compose_node(parent, index)

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:  # an unhashable key: the safe loader names it
                    raise ConstructorError(
                        None, None, "found an unhashable key", key_node.start_mark
                    ) from None
                if duplicate:
                    raise Refused(None, None, f"duplicate key {key!r}", key_node.start_mark)
                seen.add(key)
        return super().construct_mapping(node, deep=deep)


def load(text: str) -> Any:
    """The document of ``text`` (yaml.YAMLError, `Refused` included, when it is not one)."""
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass

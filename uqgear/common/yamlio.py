"""YAML reading with YAML 1.2 number rules.

PyYAML follows YAML 1.1, which reads ``206e9`` or ``1.0e9`` (no sign in the
exponent) as strings. Engineers write numbers that way, so uqgear's loader
resolves them as floats.

It also refuses what a hand-written study or design never needs and a
hostile or broken file can abuse: a key given twice in one mapping (YAML
would silently keep the last), aliases that expand a small file into a huge
document, and nesting deeper than Python's recursion allows.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

from .errors import shown

#: Most values (scalars, lists and mappings, each alias counted at every use) a document may hold.
MAX_VALUES = 200_000


class _Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 floats that refuses duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        if isinstance(node, yaml.MappingNode):
            self.flatten_mapping(node)
            lines: dict[Any, int] = {}
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                try:
                    first = lines.get(key)
                except TypeError:
                    continue  # unhashable: the base constructor reports it
                if first is not None:
                    raise yaml.constructor.ConstructorError(
                        None,
                        None,
                        f"key {shown(key, 60)} appears twice in one mapping "
                        f"(lines {first + 1} and {key_node.start_mark.line + 1}); keep one",
                        key_node.start_mark,
                    )
                lines[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


_FLOAT = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
    re.X,
)
_Loader.yaml_implicit_resolvers = {
    key: [(tag, regexp) for tag, regexp in resolvers if tag != "tag:yaml.org,2002:float"]
    for key, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))


def _expanded_size(document: Any) -> int:
    """Number of values in ``document`` with every alias counted where it is used.

    Shared sub-documents (aliases) are sized once and reused, so this costs
    one pass over the distinct values however large the expansion is.
    """
    sizes: dict[int, int] = {}
    stack: list[tuple[Any, bool]] = [(document, False)]
    while stack:
        value, children_done = stack.pop()
        if id(value) in sizes:
            continue
        if isinstance(value, dict):
            children = [*value.keys(), *value.values()]
        elif isinstance(value, list):
            children = value
        else:
            sizes[id(value)] = 1
            continue
        if children_done:
            sizes[id(value)] = min(1 + sum(sizes[id(child)] for child in children), MAX_VALUES + 1)
        else:
            stack.append((value, True))
            stack.extend((child, False) for child in children if id(child) not in sizes)
    return sizes[id(document)]


def load_yaml(text: str) -> Any:
    """Parse YAML text with YAML 1.2 float rules (``1e9`` is a float).

    Raises
    ------
    yaml.YAMLError
        Not valid YAML, a key given twice in one mapping, more than
        :data:`MAX_VALUES` values once aliases are expanded, or nesting too
        deep to read.
    """
    try:
        document = yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader derives from SafeLoader
    except RecursionError:
        raise yaml.YAMLError("the document is nested too deeply to read") from None
    if isinstance(document, (dict, list)) and _expanded_size(document) > MAX_VALUES:
        raise yaml.YAMLError(
            f"the document expands to more than {MAX_VALUES:,} values through "
            "aliases (&anchor / *alias); a study or design needs far fewer"
        )
    return document


YAMLError = yaml.YAMLError

__all__ = ["load_yaml", "YAMLError"]

"""Reading settings files: YAML or JSON mappings, with one-line errors for every way they fail.

Duplicated keys are refused (YAML would silently keep the last), a file that is not UTF-8 or
nests absurdly deep is an error that says so, and the YAML syntax error names its line.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from napari_ssdpc.errors import SsdpcError

__all__ = ["read_mapping"]


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping."""


def _mapping(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: set = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            line = key_node.start_mark.line + 1
            raise SsdpcError(f"key '{key}' is given twice (line {line}); keep one")
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def _no_duplicates(pairs: list) -> dict:
    keys = [k for k, _ in pairs]
    for k in keys:
        if keys.count(k) > 1:
            raise SsdpcError(f"key '{k}' is given twice; keep one")
    return dict(pairs)


def read_mapping(path: str | Path, what: str = "settings file") -> dict[str, Any]:
    """Read a YAML (or JSON) file that holds one mapping.

    Parameters
    ----------
    path : str or Path
        The file. ``.json`` files are read as JSON, everything else as YAML.
    what : str
        What the file is, for the messages ("optics file", "calibration").

    Returns
    -------
    dict
        The mapping.

    Raises
    ------
    SsdpcError
        Missing file, not UTF-8, bad syntax, duplicated key, too deep, or not a mapping.
    """
    path = Path(path)
    if not path.is_file():
        hint = " (it is a folder)" if path.is_dir() else ""
        raise SsdpcError(f"{what} not found: {path}{hint}; check the path")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise SsdpcError(f"{path}: not a text file in UTF-8; give a YAML or JSON {what}") from None
    except OSError as e:
        raise SsdpcError(f"{path}: cannot be read ({e.strerror}); check its permissions") from None
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text, object_pairs_hook=_no_duplicates)
        else:
            data = yaml.load(text, Loader=_StrictLoader)
    except SsdpcError as e:
        raise SsdpcError(f"{path}: {e}") from None
    except RecursionError:
        raise SsdpcError(f"{path}: nested too deeply to be a {what}; check the file") from None
    except json.JSONDecodeError as e:
        raise SsdpcError(f"{path}: not valid JSON at line {e.lineno}; fix the syntax") from None
    except yaml.YAMLError as e:
        line = getattr(getattr(e, "problem_mark", None), "line", None)
        where = f" at line {line + 1}" if line is not None else ""
        raise SsdpcError(f"{path}: not valid YAML{where}; fix the syntax") from None
    if not isinstance(data, dict):
        raise SsdpcError(f"{path}: expected a mapping of keys, got {type(data).__name__}; is this a {what}?")
    return data

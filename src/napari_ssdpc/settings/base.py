"""The base of every settings model: strict types, unknown keys refused, one-line errors.

A settings model reads a mapping (from YAML, JSON, the CLI or a widget). Strings are never
numbers or booleans (``flip_x: "false"`` is an error, not ``True``), integers are never
truncated floats, and an unknown key is refused with the nearest valid key. Pydantic's
validation errors become one :class:`~napari_ssdpc.errors.SsdpcError` line that names the key,
the value and the fix.
"""

from __future__ import annotations

import difflib
import math
import typing
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from napari_ssdpc.errors import SsdpcError

__all__ = ["SettingsModel", "bounded", "field_range", "one_line"]

M = TypeVar("M", bound="SettingsModel")


def bounded(default: Any, lo: float, hi: float, description: str, **kw: Any) -> Any:
    """A numeric field with its physical range (inclusive) and a description that names the unit.

    Parameters
    ----------
    default : float, int or None
        Default value (``...`` for a required field).
    lo, hi : float
        Inclusive range; values outside almost always mean a wrong unit.
    description : str
        What the value is, with its unit; used in help texts, widgets and error messages.

    Returns
    -------
    pydantic FieldInfo
    """
    return Field(default, ge=lo, le=hi, description=description, allow_inf_nan=False, **kw)


def field_range(model: type[BaseModel], name: str) -> tuple[float, float]:
    """(lo, hi) of a field declared with :func:`bounded`: the one place the ranges live.

    Parameters
    ----------
    model : type of pydantic.BaseModel
        The settings model.
    name : str
        The field's name.

    Returns
    -------
    tuple of float
        The inclusive bounds; ±inf where the field has none.
    """
    lo, hi = -math.inf, math.inf
    for m in model.model_fields[name].metadata:
        lo = float(getattr(m, "ge", lo) if getattr(m, "ge", None) is not None else lo)
        hi = float(getattr(m, "le", hi) if getattr(m, "le", None) is not None else hi)
    return lo, hi


class SettingsModel(BaseModel):
    """Frozen, strict, no unknown keys; ``from_dict`` turns validation errors into one line."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, validate_default=True)

    @classmethod
    def from_dict(cls: type[M], data: Any, source: str = "settings") -> M:
        """Validate a mapping.

        Parameters
        ----------
        data : dict
            The settings, keys as in the YAML schema.
        source : str
            Where the mapping came from (a file name), for the error message.

        Returns
        -------
        The validated model.

        Raises
        ------
        SsdpcError
            One line naming the key, the value and the fix.
        """
        if not isinstance(data, dict):
            raise SsdpcError(f"{source}: expected a mapping of keys, got {type(data).__name__}")
        try:
            return cls.model_validate(data)
        except ValidationError as e:
            raise SsdpcError(one_line(e, cls, source)) from None

    def to_dict(self) -> dict:
        """Plain mapping (JSON and YAML safe) that :meth:`from_dict` reads back."""
        return self.model_dump(mode="json")

    def replace(self: M, **changes: Any) -> M:
        """A validated copy with some top-level fields changed."""
        return type(self).from_dict({**self.to_dict(), **changes}, source=type(self).__name__)


def _model_at(model: type[BaseModel], loc: tuple) -> type[BaseModel] | None:
    """The sub-model that holds the key at ``loc`` (for the nearest-key hint); an index into a
    sequence of sub-models stays with that sub-model."""
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(str(part))
        ann = getattr(field, "annotation", None)
        inner = [a for a in (ann, *typing.get_args(ann)) if isinstance(a, type) and issubclass(a, BaseModel)]
        if not inner:
            return None
        model = inner[0]
    return model


_UNITS = {"um", "mm", "nm", "px", "deg", "s", "ms", "rad", "pg"}


def _nearest(key: str, candidates: list[str]) -> str:
    stem = key.rsplit("_", 1)[0]
    for c in candidates:
        if c != key and c.rsplit("_", 1)[0] == stem and c.rsplit("_", 1)[-1] in _UNITS:
            return f" (expected '{c}': lengths carry their unit in the key)"
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.5)
    if close:
        return f"; did you mean '{close[0]}'?"
    return f" (valid keys: {', '.join(candidates)})"


_KIND = {"float": "a number", "int": "a whole number", "bool": "true or false", "string": "text"}


def _misspelling(errors: list) -> dict | None:
    """The unknown key of a misspelt required key (``wavelenght_um`` for ``wavelength_um``): pydantic
    reports the required key missing first, but the unknown one names what the user wrote."""
    missing = {tuple(e["loc"]) for e in errors if e["type"] == "missing"}
    for e in errors:
        loc = tuple(e["loc"])
        if e["type"] == "extra_forbidden" and loc:
            stem, unit = str(loc[-1]).rsplit("_", 1) if "_" in str(loc[-1]) else (str(loc[-1]), "")
            if unit in _UNITS and any(str(m[-1]).rsplit("_", 1)[0] == stem for m in missing):
                continue  # another unit of the same key: the missing key's message says to convert
            near = [str(m[-1]) for m in missing if m[:-1] == loc[:-1]]
            if difflib.get_close_matches(str(loc[-1]), near, n=1, cutoff=0.6):
                return e
    return None


def one_line(error: ValidationError, model: type[BaseModel], source: str) -> str:
    """One message for the first error of a pydantic ValidationError.

    Parameters
    ----------
    error : pydantic.ValidationError
        The error raised while validating ``model``.
    model : type of pydantic.BaseModel
        The model that was validated (for the nearest valid key and the field's range).
    source : str
        Where the values came from (a file name), to start the message.

    Returns
    -------
    str
        ``"SOURCE: key: what is wrong; the fix"`` on one line.
    """
    errors = error.errors()
    misspelt = _misspelling(errors)
    first = misspelt or errors[0]
    loc = tuple(p for p in first["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    key = ".".join(str(p) for p in loc)
    value = first.get("input")
    kind = first["type"]
    sub = _model_at(model, loc) if loc else None
    if kind == "extra_forbidden":
        hint = _nearest(str(loc[-1]), list(sub.model_fields)) if sub is not None else ""
        msg = f"unknown key '{key}'{hint}"
    elif kind == "missing":
        hint = ""
        if sub is not None and isinstance(value, dict):
            found = [k for k in value if k.rsplit("_", 1)[0] == str(loc[-1]).rsplit("_", 1)[0]]
            if found:
                hint = f" (found '{found[0]}' instead: convert the value and rename the key to '{loc[-1]}')"
        msg = f"missing key '{key}'{hint}"
    elif kind.endswith("_type") or kind.endswith("_parsing"):
        what = _KIND.get(kind.split("_")[0], kind.split("_")[0])
        if kind == "model_type" or kind == "dict_type":
            what = "a mapping of keys"
        quoted = " (write it without quotes)" if isinstance(value, str) and kind != "string_type" else ""
        msg = f"'{key}' must be {what}, got {value!r}{quoted}"
    elif kind == "finite_number":
        msg = f"'{key}' must be a finite number, got {value!r}"
    elif kind in ("greater_than_equal", "less_than_equal", "greater_than", "less_than"):
        lo, hi = field_range(sub, str(loc[-1])) if sub is not None and loc else (-math.inf, math.inf)
        desc = sub.model_fields[str(loc[-1])].description if sub is not None and loc else ""
        if lo >= 0 and isinstance(value, (int, float)) and value <= 0 < hi:
            msg = f"'{key}' must be positive, got {value!r} ({desc})"
        else:
            msg = f"'{key}' = {value!r} is outside {lo:g} to {hi:g}; check the unit ({desc})"
    elif kind == "literal_error":
        msg = f"'{key}' must be {first['ctx']['expected']}, got {value!r}"
    elif kind == "value_error":
        msg = str(first["ctx"]["error"]) if "ctx" in first else first["msg"]
    else:
        msg = f"'{key}': {first['msg']}, got {value!r}"
    others = len(errors) - 1 - (misspelt is not None)  # a misspelling is also reported as the key missing
    more = f" (and {others} more)" if others > 0 else ""
    return f"{source}: {msg}{more}"

"""Type checks of values read from files (TOML configs, baseline JSON) against the
dataclass fields they will fill, with messages that name the key and the expected type."""

from __future__ import annotations

import enum
import types
import typing

from credcli.engine.config import DiagnosisConfig
from credcli.errors import CredcliError

SEGMENT_HINTS = {"window": str, "whole": bool}
"""The keys of [segments] and of a run's segmentation parameters, with their types."""


def diagnosis_hints() -> dict:
    """The keys of [diagnosis] (every DiagnosisConfig field, and the seed) with their types.

    Returns
    -------
    dict of str to type
        Each key's type hint, resolved (``typing.get_type_hints``), for :func:`check_types`.
    """
    return typing.get_type_hints(DiagnosisConfig) | {"seed": int}


def _describe(hint) -> str:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(h) for h in typing.get_args(hint) if h is not type(None))
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {'strings' if args[0] is str else 'numbers'}"
        return f"a list of {len(args)} numbers (or 'lo:hi')"
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return "one of " + ", ".join(repr(m.value) for m in hint)
    return {int: "an integer", float: "a number", str: "a string", bool: "true or false"}.get(
        hint, getattr(hint, "__name__", str(hint))
    )


def is_number(value) -> bool:
    """Whether a value read from TOML or JSON is a number credcli can take as a float: a
    float, or an int (not a bool) within the float range (an integer of 400 digits is
    not: converting it overflows).

    Parameters
    ----------
    value : object
        The value.

    Returns
    -------
    bool
        True for a float or a convertible int.

    Examples
    --------
    >>> is_number(2), is_number(2.5), is_number(True), is_number(10**400)
    (True, True, False, False)
    """
    if isinstance(value, float):
        return True
    if not isinstance(value, int) or isinstance(value, bool):
        return False
    try:
        float(value)
    except OverflowError:
        return False
    return True


def _type_ok(value, hint) -> bool:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_type_ok(value, h) for h in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return isinstance(value, (list, tuple)) and all(_type_ok(v, args[0]) for v in value)
        return isinstance(value, str) or (
            isinstance(value, (list, tuple))
            and len(value) == len(args)
            and all(_type_ok(v, a) for a, v in zip(args, value))
        )
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return isinstance(value, str) and value in {m.value for m in hint}
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:  # every integer setting of credcli fits 64 bits
        return isinstance(value, int) and not isinstance(value, bool) and -(2**63) <= value < 2**63
    if hint is float:
        return is_number(value)
    if hint is str:
        return isinstance(value, str)
    return True


def _wide_integer(value, hint) -> bool:
    """Whether ``value`` is an integer that ``hint`` (or one of its Union members) would
    take as an int but for its 64 bits."""
    if isinstance(value, bool) or not isinstance(value, int):
        return False
    origin = typing.get_origin(hint)
    members = typing.get_args(hint) if origin in (typing.Union, types.UnionType) else (hint,)
    return int in members


def check_types(section: dict, hints: dict, where: str) -> None:
    """Each config value against its field's type, naming the key and the expected type.

    An int is a number where a float is expected (if a float can hold it); a bool is
    neither; an integer setting must fit 64 bits. Keys without a hint are not checked
    here.

    Parameters
    ----------
    section : dict
        The values read (one TOML table, or a baseline's parameters).
    hints : dict of str to type
        The type of each key (:func:`diagnosis_hints`, ``SEGMENT_HINTS``).
    where : str
        Where the values come from (the file and table), for the message.

    Raises
    ------
    CredcliError
        For the first value whose type does not match, naming the key, the expected type
        and the value.

    Examples
    --------
    >>> check_types({"window": 5}, SEGMENT_HINTS, "credcli.toml [segments]")
    Traceback (most recent call last):
      ...
    credcli.errors.CredcliError: credcli.toml [segments]: window must be a string; got int 5
    """
    for key, value in section.items():
        hint = hints.get(key)
        if hint is not None and not _type_ok(value, hint):
            if _wide_integer(value, hint):
                raise CredcliError(
                    f"{where}: {key} must be an integer within ±2^63 (64 bits); got {value}"
                )
            raise CredcliError(
                f"{where}: {key} must be {_describe(hint)}; got {type(value).__name__} {value!r}"
            )

"""JSON text as ``json.JSONEncoder(indent=2, allow_nan=False)`` writes it, byte for byte,
streamed a record at a time.

The standard library encodes an indented document in pure Python, one generator frame per
value. Here a record is one string made by joins, its strings escaped by :mod:`json`'s C
escaper and its numbers spelled by their own ``__repr__`` as :mod:`json` spells them: the
same bytes with less work (measurements in docs/performance.md)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from json.encoder import encode_basestring_ascii

INDENT = "  "
"""Two spaces per level, as ``indent=2``."""


def _float(value: float) -> str:
    if value != value or value in (math.inf, -math.inf):
        raise ValueError("Out of range float values are not JSON compliant: " + repr(value))
    return float.__repr__(value)


def _key(key) -> str:
    """A dict key as :mod:`json` writes it: a string, or a number, boolean or None as the
    text of its JSON value (:func:`encode`)."""
    if isinstance(key, str):
        return encode_basestring_ascii(key)
    if key is None or isinstance(key, (int, float)):  # bool is an int
        return encode_basestring_ascii(encode(key))
    raise TypeError(f"keys must be str, int, float, bool or None, not {key.__class__.__name__}")


def _null(value) -> str:
    return "null"


_SCALARS = {
    str: encode_basestring_ascii,
    type(None): _null,
    bool: {True: "true", False: "false"}.__getitem__,
    int: int.__repr__,
    float: _float,
}
"""How each exact scalar type is written (subclasses, such as str enums, take
:func:`encode`'s isinstance path, as :mod:`json` checks them)."""
_KEYS: dict = {}
"""Written string keys with their separator, ``'"key": '`` (records share their keys)."""
MAX_KEYS = 4096
"""Most keys :data:`_KEYS` remembers."""
_PADS = ["\n" + INDENT * level for level in range(64)]


def _pad(level: int) -> str:
    return _PADS[level] if level < len(_PADS) else "\n" + INDENT * level


def encode(value, level: int = 0) -> str:
    """``value`` as indented JSON text whose first line is at ``level``.

    The text of ``json.dumps(value, indent=2, allow_nan=False)`` nested ``level`` deep:
    every line after the first is indented by ``level + 1`` steps of :data:`INDENT`, the
    closing bracket by ``level``.

    Parameters
    ----------
    value : object
        A JSON value: str, int, float, bool, None, or a list, tuple or dict of them
        (subclasses included, as :mod:`json` takes them). Dict keys may be str, int,
        float, bool or None; non-string keys are written as the text of their value.
    level : int, default 0
        How deep the value is nested (0 for a whole document).

    Returns
    -------
    str
        The JSON text, without a trailing newline.

    Raises
    ------
    ValueError
        If a float is NaN or infinite (``allow_nan=False``).
    TypeError
        If a value, or a dict key, has a type JSON cannot write.

    Examples
    --------
    >>> import json
    >>> doc = {"a": [1, 2.5, None], "b": {"c": "é"}, 3: True}
    >>> encode(doc) == json.dumps(doc, indent=2, allow_nan=False)
    True
    >>> print(encode([1, {"k": "v"}]))
    [
      1,
      {
        "k": "v"
      }
    ]
    """
    write = _SCALARS.get(value.__class__)
    if write is not None:
        return write(value)
    if isinstance(value, str):
        return encode_basestring_ascii(value)
    if value is None:
        return "null"
    if value is True:
        return "true"
    if value is False:
        return "false"
    if isinstance(value, int):
        return int.__repr__(value)
    if isinstance(value, float):
        return _float(value)
    inner = _pad(level + 1)
    if isinstance(value, (list, tuple)):
        if not value:
            return "[]"
        items = [
            write(item) if (write := _SCALARS.get(item.__class__)) else encode(item, level + 1)
            for item in value
        ]
        return "[" + inner + ("," + inner).join(items) + _pad(level) + "]"
    if isinstance(value, dict):
        if not value:
            return "{}"
        items = []
        for k, v in value.items():
            head = _KEYS.get(k) if k.__class__ is str else None
            if head is None:
                head = _key(k) + ": "
                if k.__class__ is str and len(_KEYS) < MAX_KEYS:
                    _KEYS[k] = head
            write = _SCALARS.get(v.__class__)
            items.append(head + (write(v) if write is not None else encode(v, level + 1)))
        return "{" + inner + ("," + inner).join(items) + _pad(level) + "}"
    raise TypeError(f"Object of type {value.__class__.__name__} is not JSON serializable")


def encode_rows(shared: dict, columns: dict[str, list], count: int, level: int = 0) -> list[str]:
    """The texts of ``count`` dicts that differ only at the keys of ``columns``, each as
    :func:`encode` writes it at ``level``: dict k is ``shared | {key: columns[key][k]}``
    (the keys in ``shared``'s order). One template is made from ``shared`` and filled
    with each column's texts, so that a column of floats or strings costs one C call a
    value, not a Python call (10⁶ records of one-epoch segments).

    Parameters
    ----------
    shared : dict
        The dicts' keys in order, and the values they share.
    columns : dict of str to list
        The values at the other keys, ``count`` each.
    count : int
        The number of dicts.
    level : int
        The level of each dict's first line.

    Returns
    -------
    list of str
        Each dict's text.
    """
    holes: list[list[str]] = []
    items = []
    made: dict[int, tuple[str, list]] = {}  # a column met twice is written once
    for key, value in shared.items():
        head = (_KEYS.get(key) or _key(key) + ": ").replace("%", "%%")
        if key in columns:
            column = columns[key]
            if id(column) not in made:
                made[id(column)] = _column_texts(column, level + 1)
            form, texts = made[id(column)]
            items.append(head + form)
            holes.extend(texts)
        else:
            items.append(head + encode(value, level + 1).replace("%", "%%"))
    inner = _pad(level + 1)
    template = "{" + inner + ("," + inner).join(items) + _pad(level) + "}"
    if not holes:
        return [template % ()] * count
    return list(map(template.__mod__, zip(*holes)))


def _column_texts(values: list, level: int) -> tuple[str, list[list[str]]]:
    """(a %-template of one value's text at ``level``, the texts that fill its holes, a
    list per hole): a column of one scalar type takes its writer, a column of lists of one
    length is a column per position; anything else is written value by value."""
    if isinstance(values, ListColumn):
        return _list_texts(values.positions, level)
    kinds = set(map(type, values))
    if len(kinds) == 1:
        kind = kinds.pop()
        if kind is float and all(map(math.isfinite, values)):
            return "%s", [list(map(float.__repr__, values))]
        if kind is str:
            return "%s", [list(map(encode_basestring_ascii, values))]
        if kind is int:
            return "%s", [list(map(int.__repr__, values))]
        if kind is type(None):
            return "null", []
        if kind is list and len(set(map(len, values))) == 1:
            return _list_texts([list(position) for position in zip(*values)], level)
    return "%s", [[encode(value, level) for value in values]]


def _list_texts(positions, level: int) -> tuple[str, list[list[str]]]:
    """:func:`_column_texts` of lists of one length, given as their positions' columns."""
    if not positions:
        return "[]", []
    forms, holes = [], []
    for position in positions:
        form, texts = _column_texts(position, level + 1)
        forms.append(form)
        holes.extend(texts)
    inner = _pad(level + 1)
    return "[" + inner + ("," + inner).join(forms) + _pad(level) + "]", holes


class ListColumn(Sequence):
    """A column of lists of one length, held by position, without a list per item: item k
    is ``[p[k] for p in positions]``. :func:`encode_rows` writes it position by position.

    Parameters
    ----------
    positions : sequence of list
        One column per position of the lists, of one length (at least one position).
    """

    def __init__(self, positions) -> None:
        self.positions = tuple(positions)

    def __len__(self) -> int:
        return len(self.positions[0])

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        return [p[k] for p in self.positions]


def iterencode(
    document: dict, streamed: str, piece: int, texts: Iterable[list[str]] | None = None
) -> Iterator[str]:
    """The text of ``document`` in pieces of about ``piece`` characters.

    Its list under the key ``streamed`` is encoded one item at a time, so that a document
    of a million records is never held as one string. The pieces joined are
    ``encode(document)``, byte for byte.

    Parameters
    ----------
    document : dict
        The JSON document (a dict at the top level).
    streamed : str
        The key whose list (or tuple) is streamed item by item; any other value, or an
        empty list, is written in one piece.
    piece : int
        The number of characters after which a piece is yielded (a piece ends at the
        first record boundary past it, so it may be longer).
    texts : iterable of list of str, optional
        The streamed list's items' texts (each as :func:`encode` writes it at level 2), in
        lists of consecutive items, when the caller makes them (:func:`encode_rows`); the
        streamed value is then not read, and texts of no item write ``[]``.

    Yields
    ------
    str
        Consecutive pieces of the JSON text, without a trailing newline.

    Raises
    ------
    ValueError, TypeError
        As :func:`encode`, for a value JSON cannot write.

    Examples
    --------
    >>> doc = {"version": 1, "segments": [{"n": k} for k in range(3)]}
    >>> pieces = list(iterencode(doc, "segments", 20))
    >>> len(pieces) > 1, "".join(pieces) == encode(doc)
    (True, True)
    """
    out: list[str] = []
    size = 0
    inner = "\n" + INDENT
    if not document:
        yield "{}"
        return
    out.append("{")
    for i, (key, value) in enumerate(document.items()):
        head = ("," if i else "") + inner + _key(key) + ": "
        if key != streamed or not (texts is not None or isinstance(value, (list, tuple))):
            out.append(head + encode(value, 1))
            size += len(out[-1])
        elif not value:
            out.append(head + "[]")
            size += len(out[-1])
        else:
            out.append(head + "[")
            chunks = texts if texts is not None else ([encode(item, 2)] for item in value)
            separator, first = ",\n" + INDENT * 2, "\n" + INDENT * 2
            before = first
            for chunk in chunks:
                if not chunk:
                    continue
                text = before + separator.join(chunk)
                before = separator
                out.append(text)
                size += len(text)
                if size >= piece:
                    yield "".join(out)
                    out, size = [], 0
            if before is first:  # texts of no item (streamed ones): the empty list
                out[-1] = head + "[]"
            else:
                out.append(inner + "]")
        if size >= piece:
            yield "".join(out)
            out, size = [], 0
    out.append("\n}")
    yield "".join(out)

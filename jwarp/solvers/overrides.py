"""Options spelled once: the public solver functions (:func:`jwarp.ik`, :func:`jwarp.plan`,
:func:`jwarp.calibrate`) take ``options=None, **overrides`` instead of re-listing the fields
of their options dataclass as keywords.

:func:`with_overrides` builds the options of one call: the dataclass built from the
overrides (``options`` None), or a copy of ``options`` with the overrides replaced
(``dataclasses.replace``: an override wins over the same field of ``options``). The
caller's ``options`` object is never modified.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")


def option_names(cls: type) -> tuple[str, ...]:
    """The field names of the options dataclass ``cls`` (the valid overrides)."""
    return tuple(f.name for f in dataclasses.fields(cls))


def with_overrides(func: str, cls: type[T], options: T | None,
                   overrides: Mapping[str, Any]) -> T:
    """The options of one call of ``func``: ``cls(**overrides)`` when ``options`` is None,
    else ``dataclasses.replace(options, **overrides)`` (a copy; an override wins).

    Args:
        func: the public function's name, for the messages.
        cls: its options dataclass.
        options: an instance of ``cls`` or None.
        overrides: {field name: value}.

    Raises:
        TypeError: an override that is not a field of ``cls`` (naming it and listing the
            fields), ``options`` not a ``cls``, or a required field (one without a
            default) neither in ``options`` nor in the overrides.
    """
    names = option_names(cls)
    for key in overrides:
        if key not in names:
            raise TypeError(f"{func}() got an unexpected option {key!r}; options are the "
                            f"fields of {cls.__name__}: {', '.join(names)}")
    if options is None:
        missing = [f.name for f in dataclasses.fields(cls)
                   if f.default is dataclasses.MISSING
                   and f.default_factory is dataclasses.MISSING and f.name not in overrides]
        if missing:
            raise TypeError(f"{func}() missing the option {missing[0]!r} (a keyword, or "
                            f"options={cls.__name__}({missing[0]}=...))")
        return cls(**overrides)
    if not isinstance(options, cls):
        raise TypeError(f"options: expected {cls.__name__} or None, got "
                        f"{type(options).__name__}")
    return dataclasses.replace(options, **overrides)

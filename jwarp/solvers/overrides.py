"""Options spelled once: the public solver functions (:func:`jwarp.ik`, :func:`jwarp.plan`,
:func:`jwarp.calibrate`) take ``options=None, **overrides`` instead of re-listing the fields
of their options dataclass as keywords.

:func:`with_overrides` builds the options of one call: the dataclass built from the
overrides (``options`` None), or a copy of ``options`` with the overrides replaced
(``dataclasses.replace``: an override wins over the same field of ``options``). The
caller's ``options`` object is never modified.

One vocabulary (issue 28): a most-iterations count is ``iterations`` (``<what>_iterations``
where an options class has a second one), a number of random starts is ``n_starts``, given
start configurations are ``seeds``, the kind of starts drawn is ``start_kind``, and early
stopping is ``freeze_solved`` (a solved problem stops its other starts),
``freeze_feasible`` (a feasible start stops) and ``stop_when_solved`` (the call ends). The
names they replace keep working for one release with a ``DeprecationWarning``:
:func:`renamed_options` on the dataclass (constructor, attribute reads) and
:func:`with_overrides` for the ``**overrides`` of ``ik``/``plan``/``calibrate``.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")

#: the attribute of an options dataclass holding its {old name: new name}
RENAMED = "RENAMED_OPTIONS"


def renamed(cls: type) -> dict[str, str]:
    """{old name: new name} of the options dataclass ``cls`` (empty for none)."""
    return getattr(cls, RENAMED, {})


def translate(owner: str, renames: Mapping[str, str], kwargs: dict[str, Any],
              stacklevel: int = 3) -> dict[str, Any]:
    """``kwargs`` with the old names of ``renames`` replaced by the new ones, each with a
    ``DeprecationWarning`` naming ``owner``; TypeError when both an old name and its new
    one are given."""
    if not renames or not any(k in renames for k in kwargs):
        return kwargs
    out = dict(kwargs)
    for old, new in renames.items():
        if old in out:
            if new in out:
                raise TypeError(f"{owner}: got both {old!r} and its new name {new!r}")
            warnings.warn(f"{owner}: {old!r} is renamed {new!r}; the old name is removed in "
                          f"the next release", DeprecationWarning, stacklevel=stacklevel)
            out[new] = out.pop(old)
    return out


def renamed_argument(func: str, old: str, new: str, kwargs: dict[str, Any], value: Any,
                     default: Any = None) -> Any:
    """The value of keyword ``new`` of a call of ``func`` whose ``**kwargs`` may still hold
    its old name ``old``: popped from ``kwargs`` and taken with a ``DeprecationWarning``
    (pointing at ``func``'s caller). TypeError when both are given (``value`` is not
    ``default``)."""
    if old not in kwargs:
        return value
    given = {old: kwargs.pop(old)}
    if value is not default:
        given[new] = value
    return translate(func, {old: new}, given, stacklevel=4)[new]


def renamed_options(**renames: str) -> Any:
    """Class decorator of an options dataclass whose fields ``renames`` (old=new) were
    renamed: the constructor still takes the old names, and reading an old attribute
    gives the new one, each with a ``DeprecationWarning`` (for one release).
    ``inspect.signature`` shows the new fields only."""
    def decorate(cls: type) -> type:
        init = cls.__init__  # type: ignore[misc]

        @functools.wraps(init)
        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            init(self, *args, **translate(cls.__name__, renames, kwargs))

        cls.__init__ = __init__  # type: ignore[misc]
        setattr(cls, RENAMED, dict(renames))
        for old, new in renames.items():
            setattr(cls, old, property(functools.partial(_old_attribute, name=cls.__name__,
                                                         old=old, new=new),
                                       doc=f"Deprecated name of :attr:`{new}`."))
        return cls
    return decorate


def _old_attribute(self: Any, name: str, old: str, new: str) -> Any:
    warnings.warn(f"{name}.{old} is renamed {name}.{new}; the old name is removed in the next "
                  f"release", DeprecationWarning, stacklevel=2)
    return getattr(self, new)


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

    An old name of a renamed field (:func:`renamed_options`) is taken as its new name, with
    a ``DeprecationWarning``.

    Raises:
        TypeError: an override that is not a field of ``cls`` (naming it and listing the
            fields), ``options`` not a ``cls``, or a required field (one without a
            default) neither in ``options`` nor in the overrides.
    """
    names = option_names(cls)
    overrides = translate(f"{func}()", renamed(cls), dict(overrides), stacklevel=4)
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

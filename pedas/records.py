"""Frozen records made once per control step, without the per-field cost of a frozen dataclass's ``__init__``.

A frozen dataclass refuses attribute assignment, so the ``__init__`` that :func:`dataclasses.dataclass` generates
stores every field through ``object.__setattr__``, a generic call per field: for the 17 fields of an
:class:`pedas.controller.Advisory` that is several microseconds, every 0.2 s sample, and a drive makes six such
records per sample (advisory, HUD state, context and advice, the HUD frame, the leader).

:func:`fast_init` gives a frozen dataclass an ``__init__`` with the same parameters and defaults that writes the
fields into the instance's ``__dict__`` directly, in field order. Everything else stays the dataclass's own:
assignment still raises ``FrozenInstanceError``; eq, hash, repr, :func:`dataclasses.asdict`,
:func:`dataclasses.replace` and pickling see the same fields and values.
"""
from __future__ import annotations

import dataclasses

__all__ = ["fast_init"]


def fast_init(cls: type) -> type:
    """Class decorator (above ``@dataclass(frozen=True)``): replace the generated ``__init__`` by one that fills
    ``self.__dict__`` directly. Only for frozen dataclasses with an instance ``__dict__`` (no slots), plain defaults
    (no default_factory), no ``__post_init__`` and no keyword-only or init=False fields: anything else is a
    TypeError, so that no record silently loses a behaviour of the generated ``__init__``."""
    params = getattr(cls, "__dataclass_params__", None)
    if params is None or not params.frozen:
        raise TypeError(f"{cls.__name__}: fast_init is for frozen dataclasses")
    if "__slots__" in cls.__dict__ or hasattr(cls, "__post_init__"):
        raise TypeError(f"{cls.__name__}: fast_init needs an instance __dict__ and no __post_init__")
    fields = dataclasses.fields(cls)
    defaults: dict[str, object] = {}
    args = []
    for f in fields:
        if not f.init or f.kw_only or f.default_factory is not dataclasses.MISSING:
            raise TypeError(f"{cls.__name__}.{f.name}: fast_init takes plain positional-or-keyword fields only")
        if f.default is dataclasses.MISSING:
            args.append(f.name)
        else:
            defaults[f"_default_{f.name}"] = f.default
            args.append(f"{f.name}=_default_{f.name}")
    body = "".join(f"    d[{f.name!r}] = {f.name}\n" for f in fields)
    source = f"def __init__(self, {', '.join(args)}):\n    d = self.__dict__\n{body}"
    namespace: dict[str, object] = {}
    exec(source, defaults, namespace)   # the way dataclasses builds its own __init__
    init = namespace["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__module__ = cls.__module__
    cls.__init__ = init
    return cls

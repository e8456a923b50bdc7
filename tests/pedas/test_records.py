"""pedas.records.fast_init: the per-step records keep every behaviour of the frozen dataclass they are."""
from __future__ import annotations

import dataclasses
import inspect
import pickle

import pytest

from pedas.controller import Advisory
from pedas.hud import HudAdvice, HudContext, HudState
from pedas.hud_frame import HudFrame
from pedas.records import fast_init
from pedas.traffic import Leader

RECORDS = (Advisory, HudAdvice, HudContext, HudState, HudFrame, Leader)


def _values(cls) -> dict:
    """A distinct value for every field (the field's position, as int)."""
    return {f.name: i for i, f in enumerate(dataclasses.fields(cls))}


def _reference(cls, values: dict):
    """The instance the dataclass-generated __init__ makes: every field through object.__setattr__, in order."""
    obj = object.__new__(cls)
    for f in dataclasses.fields(cls):
        object.__setattr__(obj, f.name, values.get(f.name, f.default))
    return obj


@pytest.mark.parametrize("cls", RECORDS, ids=lambda c: c.__name__)
def test_fast_init_makes_the_dataclass_instance(cls):
    fields = dataclasses.fields(cls)
    params = list(inspect.signature(cls).parameters.values())
    assert [(p.name, p.default) for p in params] == [
        (f.name, inspect.Parameter.empty if f.default is dataclasses.MISSING else f.default) for f in fields]
    assert all(p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD for p in params)
    values = _values(cls)
    by_keyword, by_position = cls(**values), cls(*values.values())
    ref = _reference(cls, values)
    for obj in (by_keyword, by_position, pickle.loads(pickle.dumps(by_keyword))):
        assert obj == ref and hash(obj) == hash(ref) and repr(obj) == repr(ref)
        assert list(vars(obj).items()) == list(vars(ref).items())   # same fields, same order
    required = {f.name: values[f.name] for f in fields if f.default is dataclasses.MISSING}
    assert vars(cls(**required)) == vars(_reference(cls, required))   # the defaults
    assert dataclasses.replace(by_keyword, **{fields[0].name: -1}) == _reference(cls, {**values, fields[0].name: -1})
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(by_keyword, fields[0].name, 0)
    with pytest.raises(TypeError):
        cls(**values, not_a_field=1)
    if required:
        with pytest.raises(TypeError):
            cls()


def test_fast_init_refuses_what_it_would_not_keep():
    @dataclasses.dataclass
    class Mutable:
        a: int

    @dataclasses.dataclass(frozen=True)
    class Factory:
        a: list = dataclasses.field(default_factory=list)

    @dataclasses.dataclass(frozen=True)
    class Post:
        a: int

        def __post_init__(self) -> None:
            pass

    @dataclasses.dataclass(frozen=True, slots=True)
    class Slots:
        a: int

    for cls in (Mutable, Factory, Post, Slots):
        with pytest.raises(TypeError, match=cls.__name__):
            fast_init(cls)

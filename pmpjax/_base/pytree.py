"""A minimal frozen-dataclass pytree (MJX style): array fields are leaves, the rest static."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, TypeVar

import jax

T = TypeVar("T")


def static_field(**kwargs: Any) -> Any:
    """A dataclass field that is part of the treedef (hashed), not a leaf."""
    return dataclasses.field(metadata={"static": True}, **kwargs)


def pytree_dataclass(cls: type[T]) -> type[T]:
    """Frozen dataclass registered as a pytree.

    Fields are array **leaves** unless declared with :func:`static_field` (sizes, flags,
    callables: part of the treedef, hashed). Annotate leaves with an array type (``jax.Array``)
    even when the default is a Python float, so the annotation says what JAX traces.
    Unflattening bypasses ``__init__``/``__post_init__`` so validation in ``__post_init__`` runs
    only when users build the object, never when JAX rebuilds it around tracers.
    """
    cls = dataclasses.dataclass(frozen=True)(cls)
    return register_pytree_class(cls)


@functools.cache
def _split_fields(cls):
    fields = dataclasses.fields(cls)
    data = tuple(f.name for f in fields if not f.metadata.get("static", False))
    meta = tuple(f.name for f in fields if f.metadata.get("static", False))
    return data, meta


def register_pytree_class(cls: type[T]) -> type[T]:
    """Register ``cls`` as a pytree once (later calls are no-ops): a dataclass flattens into its
    leaf fields (static fields in the treedef), any other class is one static object (no leaves).

    The split is read when an object is flattened, so a base class can register its subclasses
    when they are defined (``Chain.__init_subclass__``) before ``@pytree_dataclass`` makes them
    dataclasses.
    """
    if cls.__dict__.get("_pytree_registered", False):
        return cls

    def flatten_with_keys(obj):
        if not dataclasses.is_dataclass(obj):
            return (), (False, obj)
        data, meta = _split_fields(type(obj))
        children = tuple((jax.tree_util.GetAttrKey(n), getattr(obj, n)) for n in data)
        return children, (True, tuple(getattr(obj, n) for n in meta))

    def flatten(obj):
        if not dataclasses.is_dataclass(obj):
            return (), (False, obj)
        data, meta = _split_fields(type(obj))
        return tuple(getattr(obj, n) for n in data), (True, tuple(getattr(obj, n) for n in meta))

    def unflatten(aux, children):
        is_dataclass, payload = aux
        if not is_dataclass:
            return payload
        data, meta = _split_fields(cls)
        obj = object.__new__(cls)
        for n, v in zip(data, children):
            object.__setattr__(obj, n, v)
        for n, v in zip(meta, payload):
            object.__setattr__(obj, n, v)
        return obj

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    type.__setattr__(cls, "_pytree_registered", True)
    return cls


def replace(obj: T, **changes: Any) -> T:
    """``dataclasses.replace`` without re-running validation (safe under tracing)."""
    new = object.__new__(type(obj))
    for f in dataclasses.fields(obj):
        object.__setattr__(new, f.name, changes.get(f.name, getattr(obj, f.name)))
    return new


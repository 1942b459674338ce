"""Hypothesis strategies for log records, derived from their types (`msgspec.inspect`),
so that every field of every topic, constraints included, is covered without a
strategy written by hand per topic."""

from __future__ import annotations

from hypothesis import strategies as st
from msgspec import inspect

_INT64 = (-2**63, 2**63 - 1)


def values_of(info: inspect.Type) -> st.SearchStrategy:
    """Values of one type that its JSON can carry (finite floats; null is None)."""
    match info:
        case inspect.Metadata():
            return values_of(info.type)
        case inspect.StructType():
            return st.builds(info.cls, **{field.name: values_of(field.type) for field in info.fields})
        case inspect.FloatType():
            return st.floats(min_value=info.ge, max_value=info.le, allow_nan=False, allow_infinity=False)
        case inspect.IntType():
            low = _INT64[0] if info.ge is None else info.ge
            return st.integers(min_value=low, max_value=_INT64[1] if info.le is None else info.le)
        case inspect.StrType():
            return st.text(max_size=12)
        case inspect.BoolType():
            return st.booleans()
        case inspect.LiteralType():
            return st.sampled_from(info.values)
        case inspect.NoneType():
            return st.none()
        case inspect.UnionType():
            return st.one_of([values_of(kind) for kind in info.types])
        case inspect.VarTupleType():
            return st.lists(values_of(info.item_type), min_size=info.min_length or 0,
                            max_size=info.max_length if info.max_length is not None else 3).map(tuple)
        case inspect.DictType():
            return st.dictionaries(st.text(max_size=8), values_of(info.value_type), max_size=4)
    raise TypeError(f"no strategy for {info!r}: extend values_of")


def records_of(record_type: type) -> st.SearchStrategy:
    return values_of(inspect.type_info(record_type))

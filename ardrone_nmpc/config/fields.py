"""Building blocks of the config schema: the section base class and bounded field types.

Every section is frozen, forbids unknown keys, rejects NaN/inf and booleans where a number is
expected, and validates its defaults too. The bounded types take their limits from
:mod:`ardrone_nmpc.config.limits`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from ardrone_nmpc.config.limits import MAX_COORDINATE_M, MAX_SPAN_S, MIN_SPAN_S


def invalid(message: str) -> PydanticCustomError:
    return PydanticCustomError("config", "{message}", {"message": message})


# ----------------------------------------------------------------------------- field types

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


def vector(item: Any, length: int) -> Any:
    """A fixed-length tuple of ``item``; accepts a YAML list. A wrong length is one error at the
    vector itself (not a cascade of per-item errors)."""

    def check_length(value: Any) -> Any:
        if isinstance(value, (list, tuple)) and len(value) != length:
            raise invalid(f"expected {length} values, got {len(value)}")
        return value

    return Annotated[
        tuple[item, ...],
        BeforeValidator(check_length),
        Field(json_schema_extra={"minItems": length, "maxItems": length}),
    ]


Vec2 = vector(Finite, 2)
Vec3 = vector(Finite, 3)
Vec4 = vector(Finite, 4)
PositiveVec2 = vector(Positive, 2)
PositiveVec4 = vector(Positive, 4)
# Sizes of a reference path: a kilometre is already far beyond any mocap volume, and the path
# is sampled at 2 cm for the deviation metrics (1e300 m would not fit in memory).
PathSize = Annotated[float, Field(gt=0, le=MAX_COORDINATE_M, allow_inf_nan=False)]
# Positions (m): the same cap as path sizes, so no derived point leaves the float range.
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M,
                                    allow_inf_nan=False)]
CoordinateVec2 = vector(Coordinate, 2)
CoordinateVec3 = vector(Coordinate, 3)
# Time spans (s): they become tick counts and sample counts, and divide path sizes.
Span = Annotated[float, Field(ge=MIN_SPAN_S, le=MAX_SPAN_S, allow_inf_nan=False)]
NonNegativeSpan = Annotated[float, Field(ge=0, le=MAX_SPAN_S, allow_inf_nan=False)]
PathSizeVec2 = vector(PathSize, 2)
PathSizeVec3 = vector(PathSize, 3)
PathSizeVec4 = vector(PathSize, 4)
NonNegativeVec4 = vector(NonNegative, 4)
NonNegativeVec7 = vector(NonNegative, 7)
Port = Annotated[int, Field(ge=1, le=65535)]


def auto_or_number(*, low: float, high: float, low_open: bool = False) -> Any:
    """A number in [low, high] (``(low, high]`` with ``low_open``) or the word ``auto``: one
    error line for anything else (not one per member of the union)."""
    bracket = "(" if low_open else "["

    def check(value: Any) -> Any:
        if value == "auto":
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise invalid(f"expected a number in {bracket}{low:g}, {high:g}] or 'auto', "
                          f"got {value!r}")
        v = float(value)
        if not (v > low if low_open else v >= low) or not v <= high:  # NaN fails too
            raise invalid(f"expected a number in {bracket}{low:g}, {high:g}] or 'auto', "
                          f"got {value!r}")
        return v

    return Annotated[Union[float, Literal["auto"]], BeforeValidator(check)]


def require_increasing(lower_name: str, upper_name: str) -> Callable[..., Any]:
    """Validator for ``upper_name`` that requires it to exceed ``lower_name`` (declared earlier)
    elementwise; the error is reported at ``upper_name``."""

    def check(cls: type, value: Any, info: ValidationInfo) -> Any:
        lower = info.data.get(lower_name)
        if lower is None:  # the lower field itself failed and is reported on its own
            return value
        lows = lower if isinstance(lower, tuple) else (lower,)
        highs = value if isinstance(value, tuple) else (value,)
        for i, (lo, hi) in enumerate(zip(lows, highs)):
            if not lo < hi:
                where = f" at index {i}" if isinstance(value, tuple) else ""
                raise invalid(f"must be greater than {lower_name}{where} ({hi} <= {lo})")
        return value

    return field_validator(upper_name)(classmethod(check))  # type: ignore[arg-type]


def type_words(annotation: Any) -> str:
    """What a field takes, for error messages ("an integer", "a list of numbers", …)."""
    text = str(annotation)
    if "tuple" in text:
        return "a list of numbers"
    for kind, words in ((int, "an integer"), (float, "a number"), (str, "a string")):
        if annotation is kind or (kind.__name__ in text and "Literal" not in text):
            return words
    return "a value of another type"


class Section(BaseModel):
    # validate_default: defaults go through the same checks (cross-field ones included).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False,
                              validate_default=True)

    @field_validator("*", mode="before")
    @classmethod
    def _no_booleans_as_numbers(cls, value: Any, info: ValidationInfo) -> Any:
        # Lax mode would take YAML true/false as 1/0 (horizon_steps: true → 1): a boolean is
        # valid only where the field is declared bool.
        annotation = cls.model_fields[info.field_name].annotation
        if annotation is bool:
            return value
        items = value if isinstance(value, (list, tuple)) else (value,)
        for i, item in enumerate(items):
            if isinstance(item, bool):
                where = f" at index {i}" if items is value else ""
                raise invalid(f"expected {type_words(annotation)}, got the boolean "
                               f"{str(item).lower()}{where}")
        return value


def ascii_name(value: str) -> str:
    if not value.isascii() or "\x00" in value:
        raise invalid("must be ASCII without NUL characters")
    return value

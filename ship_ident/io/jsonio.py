"""Strict JSON for records that leave the process (CLI, topics, logs): NaN and Inf become null."""

from __future__ import annotations

import json
import math


def strict_json(value):
    """``value`` as plain JSON types, NaN and Inf replaced by None (any JSON parser accepts it)."""
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        value = value.tolist()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    return value


def dumps_json(record: dict, indent: int | None = None) -> str:
    """Strict JSON text of a record (NaN/Inf as null)."""
    return json.dumps(strict_json(record), indent=indent, allow_nan=False)

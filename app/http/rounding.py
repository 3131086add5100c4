"""JSON numbers as a reader expects them: 12 significant digits, no float noise.

Sums of probabilities come out as 0.6499999999999999 or -6e-17; the API rounds every float
it answers with, while the JSON-lines export (whose hashes are computed on exact values)
and the stored rows keep them exact.
"""

from __future__ import annotations

from typing import Any

from fastapi.responses import JSONResponse

SIGNIFICANT_DIGITS = 12
# Below this a float is the residue of cancelling terms (a balance of 1 - 1), not a value.
NOISE = 1e-12


def round_number(x: float) -> float:
    if abs(x) < NOISE:
        return 0.0
    return float(f"{x:.{SIGNIFICANT_DIGITS}g}")


def rounded(value: Any) -> Any:
    """value with every float in it rounded (dicts and lists walked; bools and ints kept)."""
    if isinstance(value, float):
        return round_number(value)
    if isinstance(value, dict):
        return {k: rounded(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [rounded(v) for v in value]
    return value


class RoundedJSONResponse(JSONResponse):
    """The app's default response class, so every route's body is rounded the same way."""

    def render(self, content: Any) -> bytes:
        return super().render(rounded(content))

"""One sentence of advice from a camera's `recommendation` JSON object, for HTML and Markdown.

The object (built by the audit's advice, issue 23) is `{"action", "shift_us",
"expected_error_mean_us", "expected_error_var_us2", "current_error_mean_us", "floor_us",
"why"}`; audits written before it have none, and every function here takes `None` for that.
"""

from __future__ import annotations

import math
from typing import Any

_ACTIONS = {
    "shift_trigger": "shift the trigger by {shift} µs",
    "per_frame_compensation": "compensate per frame (no constant delay removes this error)",
    "none": "leave it",
}


def _us(value: object, fmt: str = "{:.0f}") -> str | None:
    if isinstance(value, int | float) and math.isfinite(value):
        return fmt.format(value) + " µs"
    return None


def advice_sentence(camera: str, rec: dict[str, Any] | None) -> str | None:
    """`front: shift the trigger by -1500.4 µs (Eq. 5 1605 µs now, 337 µs expected, floor
    290 µs): <why>`; None without a recommendation or with an unknown action."""
    if not rec or rec.get("action") not in _ACTIONS:
        return None
    shift = rec.get("shift_us")
    shift_text = f"{shift:+.1f}" if isinstance(shift, int | float) else "?"
    action = _ACTIONS[str(rec["action"])].format(shift=shift_text)
    figures = [
        f"Eq. 5 {text} now" if (text := _us(rec.get("current_error_mean_us"))) else "",
        f"{text} expected" if (text := _us(rec.get("expected_error_mean_us"))) else "",
        f"floor {text}" if (text := _us(rec.get("floor_us"))) else "",
    ]
    shown = ", ".join(f for f in figures if f)
    why = str(rec.get("why") or "").strip()
    return f"{camera}: {action}" + (f" ({shown})" if shown else "") + (f": {why}" if why else "")


def needs_action(rec: dict[str, Any] | None) -> bool:
    """The recommendation asks for a change (not `none`)."""
    return bool(rec) and (rec or {}).get("action") not in (None, "none")

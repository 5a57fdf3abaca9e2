"""The synchronisation audit of one log: plan, rig guess and check, `info`, the audit itself.

The public API, imported on first use (importing the package costs nothing, and
`audit.run` and `audit.inspect` import each other's steps, never this package):

    from syncaudit.audit import audit_log, inspect_log, guess_rig
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from syncaudit.audit.inspect import InfoReport, inspect_log
    from syncaudit.audit.rig_guess import guess_rig, starter_rig_yaml
    from syncaudit.audit.run import AuditResult, CameraAudit, audit_log

__all__ = [
    "AuditResult",
    "CameraAudit",
    "InfoReport",
    "audit_log",
    "guess_rig",
    "inspect_log",
    "starter_rig_yaml",
]

_HOMES = {
    "AuditResult": "syncaudit.audit.run",
    "CameraAudit": "syncaudit.audit.run",
    "audit_log": "syncaudit.audit.run",
    "InfoReport": "syncaudit.audit.inspect",
    "inspect_log": "syncaudit.audit.inspect",
    "guess_rig": "syncaudit.audit.rig_guess",
    "starter_rig_yaml": "syncaudit.audit.rig_guess",
}


def __getattr__(name: str) -> Any:
    """The public name `name`, from the module it lives in (imported now)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'syncaudit.audit' has no attribute {name!r}")
    return getattr(importlib.import_module(home), name)

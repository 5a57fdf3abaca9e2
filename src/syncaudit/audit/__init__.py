"""The synchronisation audit of one log: plan, rig guess and check, `info`, the audit itself."""
